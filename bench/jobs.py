"""Job types and the result-row schema: the leaf module every stage of a run shares.

A :class:`JobPlan` is one expected job of a table (a row on one scene with one seed at one scale); a
:class:`Job` is a plan with its resolved method config and id (:func:`bench.runner.resolve_jobs`). A
job's result is one JSON row (schema :data:`RESULT_SCHEMA`): :func:`row_head`'s identifying fields, then
``status`` ("ok" | "failed"), ``metrics`` (the final snapshot's), ``curve`` (every snapshot:
``fraction``, ``iterations``, ``seconds``, ``metrics``, ``diagnostics``), ``iterations``, ``timings``
(wall seconds per stage) and, when failed, ``error`` (``type``, ``message``, ``traceback``). Executors
add ``attempts``, ``wall_seconds``, ``worker_name``, ``executor``, ``torch_threads`` and ``blas`` (the matrix-product code path, :mod:`bench.mkl_dispatch`).

Imports nothing of the harness but the package version (layering: ``tests/test_architecture.py``).
"""

from __future__ import annotations

import datetime as _dt
import os
import platform
import socket
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

from bench import __version__
from bench.machine import cpu_description

RESULT_SCHEMA = 1
REQUIRED_FIELDS = ("job_id", "table", "row", "method", "scene", "dataset", "seed", "scale", "status")
"""Fields a stored result row must have to be read back (:func:`bench.results_io.collect_results`)."""
WORKER_LOST = "WorkerLost"
"""``error.type`` of a job whose worker process died (not the job's own error: a rerun tries again)."""


@dataclass(frozen=True)
class JobPlan:
    """One expected job of a table at a scale: a row on one scene with one seed."""

    table: str
    row: str
    method: str
    overrides: Mapping[str, Any]
    group: str
    dataset: str
    protocol: str
    scene: str
    seed: int
    scale: str
    effects: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)



@dataclass(frozen=True)
class Job:
    """A planned job with its resolved config and id."""

    plan: JobPlan
    config: dict[str, Any]
    job_id: str
    artifact_root: str | None = None  # write the job's mesh / maps under <root>/<job_id>/ (not part of the id)
    base_id: str = ""  # the id without the thread count: what tables match results by ("" = job_id)

    def __post_init__(self) -> None:
        if not self.base_id:
            object.__setattr__(self, "base_id", self.job_id)  # frozen dataclass


def is_trained(config: Any) -> bool:
    """True if a job's resolved config sets an optimisation schedule (a non-zero ``iterations``); fusion
    references (the oracle) have none."""
    return isinstance(config, dict) and bool(config.get("iterations"))


def result_path(out_dir: Path, job: Job) -> Path:
    return Path(out_dir) / "jobs" / f"{job.job_id}.json"


def versions() -> dict[str, str]:
    import numpy
    import open3d
    import torch

    return {"bench": __version__, "python": platform.python_version(), "numpy": numpy.__version__, "torch": torch.__version__, "open3d": open3d.__version__}


def row_head(job: Job) -> dict[str, Any]:
    """The identifying fields every result row starts with (the JSON schema, version 1)."""
    plan = job.plan
    return {
        "job_id": job.job_id,
        "base_id": job.base_id,
        "schema": RESULT_SCHEMA,
        "table": plan.table,
        "row": plan.row,
        "group": plan.group,
        "method": plan.method,
        "config": job.config,
        "scene": plan.scene,
        "dataset": plan.dataset,
        "protocol": plan.protocol,
        "effects": {k: dict(v) for k, v in plan.effects.items()},
        "seed": plan.seed,
        "scale": plan.scale,
        "versions": versions(),
        "cpu": cpu_description(),
        "worker": f"{socket.gethostname()}:{os.getpid()}",
        "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
    }


def failure_row(job: Job, error_type: str, message: str, tb: str) -> dict[str, Any]:
    """A ``failed`` result row (same schema as :func:`run_job`'s) for an error outside the job's code."""
    row = row_head(job)
    row.update(status="failed", metrics={}, curve=[], iterations=0, timings={},
               error={"type": error_type, "message": message, "traceback": tb})
    return row
