"""Run one job in this process: data, method, evaluation of every snapshot -> its result row.

Called by every executor on its worker (:func:`bench.executors.base.execute_job`); the row's schema is
:mod:`bench.jobs`'. Never raises for the job's own error: it is recorded in the row as ``failed``.
"""

from __future__ import annotations

import math
import time
import traceback
from pathlib import Path
from typing import Any, Callable

from bench.data.datasets import DEFAULT_CACHE, load_dataset
from bench.evaluate import evaluate_snapshot
from bench.jobs import Job, row_head
from bench.mkl_dispatch import blas_path
from methods.cpp_build import OwnClock
from methods.registry import get_method
from methods.stage_cache import stage_checkpoints

STAGE_CACHE_DIR = "_stages"
"""Folder of the dataset cache holding shared stage checkpoints (``methods.stage_cache``)."""


def method_metrics(extra: dict[str, Any]) -> dict[str, float]:
    """Metrics a method reports about itself (``unc_*``: quality of its uncertainty maps against the
    scene's GT, from the uncertainty stage), copied from ``Artifacts.extra`` into the row's metrics so
    tables can show them and claims can use them."""
    out = {}
    for k, v in extra.items():
        if k.startswith("unc_") and isinstance(v, (int, float)) and math.isfinite(float(v)):
            out[k] = float(v)
    return out


def run_job(job: Job, cache_dir: Path = DEFAULT_CACHE, progress: Callable[[float, str], None] | None = None) -> dict[str, Any]:
    """Run one job end to end (data, method, evaluation of every snapshot) and return its result row."""
    plan = job.plan
    row = row_head(job)
    timings: dict[str, float] = {}
    job_clock = OwnClock()  # a kernel build the job waited for is not its cost (wall_seconds has it)
    try:
        t = time.perf_counter()
        scene = load_dataset(plan.scene, plan.scale, cache_dir, effects=plan.effects)
        timings["data"] = time.perf_counter() - t

        method = get_method(plan.method)
        with stage_checkpoints(Path(cache_dir) / STAGE_CACHE_DIR, {"blas": blas_path()}):  # stages rows share exactly, trained once
            artifacts = method.fit(scene, job.config, plan.seed, progress)
        for stage, seconds in artifacts.timings.items():
            if stage != "total_method":
                timings[stage] = float(seconds)

        curve = []
        t = time.perf_counter()
        for i, snap in enumerate(artifacts.snapshots):
            point = {"fraction": snap.fraction, "iterations": snap.iterations, "seconds": snap.seconds}
            if snap.diagnostics:
                point["diagnostics"] = dict(snap.diagnostics)
            try:
                point["metrics"] = evaluate_snapshot(snap, scene, plan.protocol, plan.scale, seed=plan.seed)
            except ValueError as exc:  # e.g. an empty mesh early in the schedule: that point has no metrics
                if i == len(artifacts.snapshots) - 1:
                    raise  # the final result itself cannot be evaluated: the job fails, with this message
                point.update(metrics={}, error=f"{type(exc).__name__}: {exc}")
            curve.append(point)
        timings["eval"] = (time.perf_counter() - t) / max(len(artifacts.snapshots), 1)
        final = dict(curve[-1]["metrics"]) if curve else {}
        final.update(method_metrics(artifacts.extra))
        row.update(status="ok", error=None, metrics=final, curve=curve, iterations=artifacts.iterations, extra=artifacts.extra)
        if job.artifact_root:
            row["artifacts"] = _keep_artifacts(artifacts, scene, job)
    except Exception as exc:  # recorded in the row: the table marks it failed instead of dropping it
        row.update(status="failed", metrics={}, curve=[], iterations=0,
                   error={"type": type(exc).__name__, "message": str(exc), "traceback": traceback.format_exc()})
    # total: what the job cost, a shared stage it loaded (train_shared, also inside train) counted as if trained here,
    # C++ kernel builds left out; the executor's wall_seconds is what it took
    timings["total"] = job_clock.seconds() + timings.get("train_shared", 0.0)
    row["timings"] = timings
    return row


def _keep_artifacts(artifacts: Any, scene: Any, job: Job) -> dict[str, Any]:
    """Write the job's artifacts (bench.artifacts); a failure to write them is noted, not fatal."""
    from bench.artifacts import artifact_dir, write_job_artifacts

    assert job.artifact_root is not None
    folder = artifact_dir(Path(job.artifact_root), job.job_id)
    try:
        return {"dir": f"artifacts/{job.job_id}", "files": write_job_artifacts(artifacts, scene, folder)}
    except OSError as exc:
        return {"dir": None, "files": [], "error": f"{type(exc).__name__}: {exc}"}
