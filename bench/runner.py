"""Jobs: one (table row, scene, seed, scale) each; run, evaluate, and store one JSON result per job.

A job's id is a hash of what determines its result: method name, resolved method config, scene recipe
content (and scene variant, when it changes the scene), seed, scale, evaluation protocol and the code
version; not the table or row label, so identical rows of different tables are one job, run once. Results are written atomically to
``<out>/jobs/<job_id>.json``; a rerun skips jobs whose result exists (unless ``force``). A job that
raises is recorded as ``status: failed`` with its error and traceback, never silently dropped.

Where jobs run is an executor's business (``bench/executors/``: a local process pool by default, Dask
distributed for clusters); :func:`run_jobs` hands it the jobs still to do and writes each row as it
arrives. Besides the schema-1 fields of :func:`bench.execute.run_job` (:mod:`bench.jobs`), rows from :func:`run_jobs` carry
``attempts`` (1 unless a worker died), ``wall_seconds`` (on the worker, dataset preparation included),
``worker_name``, ``executor``, ``torch_threads`` and ``blas`` (the matrix-product code path, :mod:`bench.mkl_dispatch`).
"""

from __future__ import annotations

import hashlib
import json
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

from bench import __version__
from bench.data.atomic import atomic_write_json
from bench.data.datasets import DEFAULT_CACHE, check_folder_scene, scene_hash
from bench.jobs import WORKER_LOST, Job, JobPlan, is_trained, result_path
from methods.registry import available_methods, identity_config, method_config

if TYPE_CHECKING:
    from bench.executors.base import Executor


def job_id_for(plan: JobPlan, config: dict[str, Any], threads: int | None = None, scene_digest: str | None = None) -> str:
    """Stable 16-hex id of a job (see module docstring for what it covers). ``threads``: the torch threads
    the job will run with, when the executor knows it (results differ by up to ~0.003 F between thread
    counts: float sums in another order), so a row computed with another count is not silently reused;
    without it, the *base id* that tables and reports match results by. With ``threads`` the id also
    covers this process's matrix-product code path (:func:`bench.mkl_dispatch.blas_path`, which the
    local executor's workers inherit) when it is not the default one, and a config's ``flush_denormals``
    and ``coarse_gradient_pass`` when on (the base id leaves them out through
    ``id_neutral``), for the same reason. ``scene_digest``: :func:`bench.data.datasets.scene_hash` of the plan's
    scene when the caller has it already (a folder scene is hashed from its files)."""
    from bench.mkl_dispatch import blas_path

    key = {
        "method": plan.method,
        "config": identity_config(plan.method, config),
        "scene": plan.scene,
        "recipe": scene_digest or scene_hash(plan.scene, plan.effects),
        "seed": plan.seed,
        "scale": plan.scale,
        "protocol": plan.protocol,
        "version": __version__,
    }
    if threads is not None:
        key["torch_threads"] = int(threads)
        if (blas := blas_path()) != "default":
            key["blas"] = blas
        if config.get("flush_denormals"):  # a MonoSDF-family job flushes float32 denormals (left out of the base id)
            key["denormals"] = "flushed"
        if config.get("coarse_gradient_pass"):  # ... and renders its coarse samples from the sampler's pass (same)
            key["coarse_pass"] = "with_gradient"
    return hashlib.sha256(json.dumps(key, sort_keys=True, default=str).encode()).hexdigest()[:16]


def resolve_jobs(plans: list[JobPlan], threads: int | None = None) -> tuple[list[Job], list[JobPlan]]:
    """Resolve configs and ids (``threads``: see :func:`job_id_for`); returns (runnable jobs, plans whose
    method is not implemented yet)."""
    known = set(available_methods())
    jobs, pending = [], []
    configs: dict[str, dict[str, Any]] = {}  # many plans (seeds, scenes) share a config and a scene: resolved once each
    scenes: dict[str, str] = {}
    for plan in plans:
        if plan.method not in known:
            pending.append(plan)
            continue
        ckey = json.dumps([plan.method, plan.scale, plan.overrides], sort_keys=True, default=str)
        if ckey not in configs:
            configs[ckey] = method_config(plan.method, plan.scale, dict(plan.overrides))
        skey = json.dumps([plan.scene, plan.effects], sort_keys=True, default=str)
        if skey not in scenes:
            check_folder_scene(plan.scene)  # a broken dataset folder: bad input, before any job runs
            scenes[skey] = scene_hash(plan.scene, plan.effects)
        config = dict(configs[ckey])
        base = job_id_for(plan, config, scene_digest=scenes[skey])
        jobs.append(Job(plan, config, job_id_for(plan, config, threads, scenes[skey]) if threads is not None else base, base_id=base))
    return jobs, pending


def plan_index(jobs: list[Job]) -> dict[str, list[JobPlan]]:
    """Base job id -> the plans (table rows x group x scene x seed) it stands for; what
    :func:`bench.report.build_table` matches results by, so a job shared by tables counts in each."""
    index: dict[str, list[JobPlan]] = {}
    for job in jobs:
        index.setdefault(job.base_id, []).append(job.plan)
    return index


def unique_jobs(jobs: list[Job]) -> list[Job]:
    """``jobs`` without repeated ids (the first plan of each id is the one that runs and labels the row)."""
    first: dict[str, Job] = {}
    for job in jobs:
        first.setdefault(job.job_id, job)
    return list(first.values())


def training_first(jobs: list[Job]) -> list[Job]:
    """``jobs`` with those that train (an ``iterations`` setting) before those that do not (the oracle's
    fusion-only jobs, 5-10 s each), otherwise in plan order: the short jobs then fill the last minutes
    instead of one long job running alone at the end (measured: the dense table ended with a 25 s tail
    on one worker when its 12 oracle jobs ran first)."""
    return sorted(jobs, key=lambda j: 0 if is_trained(j.config) else 1)


def needs_run(path: Path, force: bool = False) -> bool:
    """True if the job stored at ``path`` must (re)run: ``force``, no stored row, or a stored failure
    whose worker died (``WorkerLost``: not the job's fault, so a rerun tries again). A job that raised
    keeps its failed row until ``force`` (it would fail again)."""
    if force or not path.exists():
        return True
    try:
        stored = json.loads(path.read_text())
    except (OSError, ValueError):
        return True  # unreadable: run it again (the write is atomic, so this is not a half-written row)
    if not isinstance(stored, dict):
        return True  # `null`, `[]`, a bare number: not a result row, run it again
    return stored.get("status") == "failed" and (stored.get("error") or {}).get("type") == WORKER_LOST


def run_jobs(
    jobs: list[Job],
    out_dir: Path,
    cache_dir: Path = DEFAULT_CACHE,
    force: bool = False,
    show_progress: bool = True,
    executor: "Executor | None" = None,
    keep_artifacts: bool = True,
) -> list[dict[str, Any]]:
    """Plan -> executor -> write each result atomically as it arrives.

    Runs every job whose result is not stored yet (all of them with ``force``; see :func:`needs_run`)
    on ``executor`` (default: :class:`~bench.executors.local.LocalExecutor` with one worker, in this
    process; jobs that train first, see :func:`training_first`), writes each row to
    ``<out_dir>/jobs/<job_id>.json`` the moment the executor reports it, and shows progress (jobs done /
    running / failed). Jobs with the same id run once. With ``keep_artifacts`` each job also writes its
    final mesh / uncertainty maps / renders to ``<out_dir>/artifacts/<job_id>/`` (:mod:`bench.artifacts`).

    Returns:
        The result rows of all jobs (stored or freshly computed), in job order.
    """
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    from bench.executors.local import LocalExecutor

    own = executor is None
    executor = LocalExecutor(workers=1) if executor is None else executor
    by_id: dict[str, Job] = {}
    for j in jobs:
        if j.job_id not in by_id and needs_run(result_path(out_dir, j), force):
            by_id[j.job_id] = j
    todo = training_first(list(by_id.values()))
    if keep_artifacts:  # meshes / maps under <out_dir>/artifacts/<job_id>/ (bench.artifacts)
        from dataclasses import replace

        todo = [replace(j, artifact_root=str(Path(out_dir) / "artifacts")) for j in todo]
    fresh: dict[str, dict[str, Any]] = {}
    done = failed = retried = running = 0
    reused = len({j.job_id for j in jobs}) - len(todo)
    if reused:
        print(f"{reused} finished job(s) reused from {Path(out_dir) / 'jobs'}"
              + (f"; {len(todo)} to run" if todo else "; nothing to run") + " (--force reruns them)", flush=True)

    if not todo:  # every job stored: no progress bar, no "0/0 done"
        if own:
            executor.close()
        return _stored_rows(jobs, {}, out_dir)

    def status() -> str:
        return (f"jobs [{executor.describe()}]: {done}/{len(todo)} done, {running} running, {failed} failed"
                + (f", {retried} retried" if retried else ""))

    # not a terminal (a nightly log, a pipe): no live bars, one plain line per job event instead
    plain = show_progress and not sys.stdout.isatty()
    t_start = time.perf_counter()

    def line(msg: str) -> None:
        if plain:
            print(f"[{time.perf_counter() - t_start:7.0f} s] {msg}", flush=True)

    try:
        with Progress(TextColumn("{task.description}"), BarColumn(), TextColumn("{task.completed}/{task.total}"),
                      TimeElapsedColumn(), disable=not show_progress or plain, transient=False) as bar:
            overall = bar.add_task(status(), total=len(todo))
            inner: dict[str, Any] = {}

            def progress_for(job: Job) -> Callable[[float, str], None]:
                task = bar.add_task(f"  {job.plan.method} | {job.plan.scene} | seed {job.plan.seed}", total=1.0)
                inner[job.job_id] = task

                def progress(frac: float, msg: str) -> None:
                    bar.update(task, completed=frac, description=f"  {msg}")

                return progress

            line(f"{len(todo)} job(s) to run [{executor.describe()}]")
            for ev in executor.run(todo, Path(cache_dir), progress_for if show_progress and not plain else None):
                if ev.kind == "started":
                    running += 1
                    line(f"started {_describe(ev.job)}")
                elif ev.kind == "status" and ev.running is not None:
                    running = ev.running
                elif ev.kind == "retry":
                    retried += 1
                    running = max(0, running - 1)
                    bar.console.print(f"[yellow]retrying[/yellow] {_describe(ev.job)} (attempt {ev.attempt}): {ev.message}")
                    line(f"retrying {_describe(ev.job)} (attempt {ev.attempt}): {ev.message}")
                elif ev.kind == "done":
                    assert ev.job is not None and ev.row is not None
                    atomic_write_json(result_path(out_dir, ev.job), ev.row)
                    fresh[ev.job.job_id] = ev.row
                    done += 1
                    running = max(0, running - 1)
                    if ev.job.job_id in inner:
                        bar.remove_task(inner.pop(ev.job.job_id))
                    if ev.row["status"] != "ok":
                        failed += 1
                        err = ev.row.get("error") or {}
                        bar.console.print(f"[red]job failed[/red] {_describe(ev.job)}: {err.get('type')}: {err.get('message')}")
                    bar.advance(overall)
                    f = (ev.row.get("metrics") or {}).get("fscore")
                    line(f"{ev.row['status']} {_describe(ev.job)}" + (f": F {f:.3f}" if isinstance(f, float) else "")
                         + f" ({(ev.row.get('timings') or {}).get('total', float('nan')):.0f} s); {status()}")
                bar.update(overall, description=status())
    finally:
        if own:
            executor.close()
    if not show_progress or plain:
        print(status())
    return _stored_rows(jobs, fresh, out_dir)


def _stored_rows(jobs: list[Job], fresh: dict[str, dict[str, Any]], out_dir: Path) -> list[dict[str, Any]]:
    """The row of every job, in job order: this run's (``fresh``) or the one stored in ``out_dir``."""
    return [fresh.get(j.job_id) or json.loads(result_path(out_dir, j).read_text()) for j in jobs]


def _describe(job: Job | None) -> str:
    return "?" if job is None else f"{job.plan.row} | {job.plan.scene} | seed {job.plan.seed}"
