"""Jobs: one (table row, scene, seed, scale) each; run, evaluate, and store one JSON result per job.

A job's id is a hash of what determines its result: method name, resolved method config, scene recipe
content, seed, scale, evaluation protocol and the code version. Results are written atomically to
``<out>/jobs/<job_id>.json``; a rerun skips jobs whose result exists (unless ``force``). A job that
raises is recorded as ``status: failed`` with its error and traceback, never silently dropped.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import os
import platform
import socket
import time
import traceback
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from bench import __version__
from bench.atomic import atomic_write_json
from bench.datasets import DEFAULT_CACHE, load_dataset, recipe_hash, recipe_path
from bench.evaluate import evaluate_snapshot
from bench.tables import JobPlan
from methods.registry import available_methods, get_method, method_config

RESULT_SCHEMA = 1


@dataclass(frozen=True)
class Job:
    """A planned job with its resolved config and id."""

    plan: JobPlan
    config: dict[str, Any]
    job_id: str


def job_id_for(plan: JobPlan, config: dict[str, Any]) -> str:
    """Stable 16-hex id of a job (see module docstring for what it covers)."""
    key = {
        "method": plan.method,
        "config": config,
        "scene": plan.scene,
        "recipe": recipe_hash(recipe_path(plan.scene)),
        "seed": plan.seed,
        "scale": plan.scale,
        "protocol": plan.protocol,
        "version": __version__,
    }
    return hashlib.sha256(json.dumps(key, sort_keys=True, default=str).encode()).hexdigest()[:16]


def resolve_jobs(plans: list[JobPlan]) -> tuple[list[Job], list[JobPlan]]:
    """Resolve configs and ids; returns (runnable jobs, plans whose method is not implemented yet)."""
    known = set(available_methods())
    jobs, pending = [], []
    for plan in plans:
        if plan.method not in known:
            pending.append(plan)
            continue
        config = method_config(plan.method, plan.scale, dict(plan.overrides))
        jobs.append(Job(plan, config, job_id_for(plan, config)))
    return jobs, pending


def result_path(out_dir: Path, job: Job) -> Path:
    return Path(out_dir) / "jobs" / f"{job.job_id}.json"


def _versions() -> dict[str, str]:
    import numpy
    import open3d
    import torch

    return {"bench": __version__, "python": platform.python_version(), "numpy": numpy.__version__, "torch": torch.__version__, "open3d": open3d.__version__}


def run_job(job: Job, cache_dir: Path = DEFAULT_CACHE, progress: Callable[[float, str], None] | None = None) -> dict[str, Any]:
    """Run one job end to end (data, method, evaluation of every snapshot) and return its result row."""
    plan = job.plan
    row: dict[str, Any] = {
        "job_id": job.job_id,
        "schema": RESULT_SCHEMA,
        "table": plan.table,
        "row": plan.row,
        "group": plan.group,
        "method": plan.method,
        "config": job.config,
        "scene": plan.scene,
        "dataset": plan.dataset,
        "protocol": plan.protocol,
        "seed": plan.seed,
        "scale": plan.scale,
        "versions": _versions(),
        "worker": f"{socket.gethostname()}:{os.getpid()}",
        "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
    }
    timings: dict[str, float] = {}
    t_start = time.perf_counter()
    try:
        t = time.perf_counter()
        scene = load_dataset(plan.scene, plan.scale, cache_dir)
        timings["data"] = time.perf_counter() - t

        method = get_method(plan.method)
        artifacts = method.fit(scene, job.config, plan.seed, progress)
        for stage, seconds in artifacts.timings.items():
            if stage != "total_method":
                timings[stage] = float(seconds)

        curve = []
        t = time.perf_counter()
        for snap in artifacts.snapshots:
            metrics = evaluate_snapshot(snap, scene, plan.protocol, plan.scale, seed=plan.seed)
            curve.append({"fraction": snap.fraction, "iterations": snap.iterations, "seconds": snap.seconds, "metrics": metrics})
        timings["eval"] = (time.perf_counter() - t) / max(len(artifacts.snapshots), 1)
        row.update(status="ok", error=None, metrics=curve[-1]["metrics"] if curve else {}, curve=curve,
                   iterations=artifacts.iterations, extra=artifacts.extra)
    except Exception as exc:  # recorded in the row: the table marks it failed instead of dropping it
        row.update(status="failed", metrics={}, curve=[], iterations=0,
                   error={"type": type(exc).__name__, "message": str(exc), "traceback": traceback.format_exc()})
    timings["total"] = time.perf_counter() - t_start
    row["timings"] = timings
    return row


def run_jobs(
    jobs: list[Job],
    out_dir: Path,
    cache_dir: Path = DEFAULT_CACHE,
    force: bool = False,
    show_progress: bool = True,
) -> list[dict[str, Any]]:
    """Run every job whose result is not stored yet (all of them with ``force``), with a progress bar.

    Returns:
        The result rows of all jobs (stored or freshly computed), in job order.
    """
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    rows: list[dict[str, Any]] = []
    todo = [j for j in jobs if force or not result_path(out_dir, j).exists()]
    with Progress(TextColumn("{task.description}"), BarColumn(), TextColumn("{task.completed}/{task.total}"),
                  TimeElapsedColumn(), disable=not show_progress, transient=False) as bar:
        overall = bar.add_task("jobs", total=len(todo))
        for job in jobs:
            path = result_path(out_dir, job)
            if job in todo:
                desc = f"{job.plan.row} | {job.plan.scene} | seed {job.plan.seed}"
                bar.update(overall, description=desc)
                inner = bar.add_task(f"  {job.plan.method}", total=1.0)

                def progress(frac: float, msg: str, _t=inner) -> None:
                    bar.update(_t, completed=frac, description=f"  {msg}")

                row = run_job(job, cache_dir, progress)
                bar.remove_task(inner)
                atomic_write_json(path, row)
                bar.advance(overall)
                if row["status"] != "ok":
                    bar.console.print(f"[red]job failed[/red] {desc}: {row['error']['type']}: {row['error']['message']}")
            else:
                row = json.loads(path.read_text())
            rows.append(row)
    return rows
