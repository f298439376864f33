"""The executor interface: where jobs run, behind one small contract.

An executor takes the jobs still to run and yields :class:`Event` s as they happen; the client
(:func:`bench.runner.run_jobs`) writes each finished job's row atomically as its ``done`` event
arrives, so whatever happens later (a crash of the client, a lost scheduler) no finished result is
lost, and a rerun skips it. Contract of :meth:`Executor.run`:

* exactly one ``done`` event per job given, carrying the job's final result row (``status`` ``ok`` or
  ``failed``), unless the run itself is aborted (then the unfinished jobs simply have no row yet and
  the table shows them as pending, never averaged away);
* a worker that dies mid-job (process killed, out of memory, machine lost) gets the job retried on
  another worker, at most ``retries`` more times; then the ``done`` row is a failure of type
  ``WorkerLost`` naming the attempts and the last error (:func:`lost_row`);
* a job that raises is not retried: :func:`bench.execute.run_job` records its error and traceback in
  the row (deterministic failures would only fail again);
* ``started`` / ``retry`` / ``status`` events feed the progress display (jobs done / running / failed).

Every job runs through :func:`execute_job` on the worker: it sets torch's thread count to the worker's
share of the machine's cores (so two jobs on two cores do not oversubscribe), synthesises the job's
dataset under a per-dataset file lock (workers share the dataset cache), runs the job and adds
``attempts``, ``wall_seconds``, ``worker_name``, ``executor``, ``torch_threads`` and ``blas`` (:func:`bench.mkl_dispatch.blas_path`) to the row.

Implementations: :class:`bench.executors.local.LocalExecutor` (process pool, the default) and
:class:`bench.executors.dask.DaskExecutor` (Dask distributed).
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import os
import socket
import sys
import time
import traceback
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterator, Literal, Sequence

from bench.jobs import WORKER_LOST, Job, failure_row

EventKind = Literal["started", "retry", "done", "status"]
ProgressFactory = Callable[["Job"], Callable[[float, str], None] | None]
DEFAULT_RETRIES = 2


@dataclass(frozen=True)
class Event:
    """One thing that happened to a job (or, for ``status``, to the run).

    ``done``: ``row`` is the job's final result row. ``retry``: ``message`` says why (the worker
    died). ``status``: ``running`` is the number of jobs executing right now (when known).
    """

    kind: EventKind
    job: "Job | None" = None
    row: dict[str, Any] | None = None
    message: str = ""
    running: int | None = None
    attempt: int = 1


@dataclass
class Executor(ABC):
    """Runs independent jobs somewhere and reports what happens (see the module docstring)."""

    retries: int = DEFAULT_RETRIES
    name: str = field(default="executor", init=False)

    @property
    @abstractmethod
    def slots(self) -> int:
        """How many jobs can run at once (for the progress display and the docs)."""

    @abstractmethod
    def run(self, jobs: Sequence["Job"], cache_dir: Path, progress_for: ProgressFactory | None = None) -> Iterator[Event]:
        """Run ``jobs``; yield events, exactly one ``done`` per job. ``progress_for(job)`` may give a
        per-job progress callback (used only where the job runs in this process)."""

    @property
    def planned_threads(self) -> int | None:
        """Torch threads every job will get, when known before the jobs run (it enters the job id,
        :func:`bench.runner.job_id_for`); None when it depends on the worker a job lands on (Dask)."""
        return None

    def close(self) -> None:
        """Release workers / connections (idempotent)."""

    def describe(self) -> str:
        return f"{self.name} ({self.slots} slot{'s' if self.slots != 1 else ''})"

    def __enter__(self) -> "Executor":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


# --------------------------------------------------------------------------------------------------
# worker side


def available_cores() -> int:
    """Cores this process may use (CPU affinity where the OS has it, else ``os.cpu_count()``)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def threads_per_job(slots_on_this_machine: int, cores: int | None = None) -> int:
    """Torch threads for one job when ``slots_on_this_machine`` jobs share the machine's cores."""
    cores = available_cores() if cores is None else cores
    return max(1, cores // max(1, slots_on_this_machine))


def set_job_threads(threads: int) -> None:
    """Limit the threads of everything a job computes with: torch's intra-op pool, open3d's own pool
    (TSDF fusion, ray casting, nearest neighbours: it ignores ``OMP_NUM_THREADS`` once loaded), and
    BLAS / OpenMP libraries not yet loaded (the environment variables, which ``metrics.nn`` also reads
    for scipy's ``workers``). Measured: with open3d unlimited, an evaluation in one worker took the
    other worker's core, and training jobs running beside evaluations slowed by ~45 %."""
    for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
        os.environ[var] = str(threads)
    import torch

    if torch.get_num_threads() != threads:
        torch.set_num_threads(threads)
    try:
        import open3d as o3d

        o3d.utility.set_max_threads(int(threads))
    except (ImportError, AttributeError):  # open3d missing or without the setting: nothing to limit
        pass


@contextlib.contextmanager
def _file_lock(path: Path) -> Iterator[None]:
    """An exclusive advisory lock (``flock``) held for the ``with`` block; no-op where unsupported."""
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        import fcntl
    except ImportError:  # not POSIX: fall back to the FileExistsError handling below
        yield
        return
    with open(path, "a+") as f:
        fcntl.flock(f.fileno(), fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(f.fileno(), fcntl.LOCK_UN)


def prepare_dataset(scene: str, scale: str, cache_dir: Path, effects: Any = None) -> None:
    """Make sure the job's dataset is in the cache, safely when several workers want it at once.

    Synthesis is serialised per dataset with a file lock in ``<cache>/.locks/`` (workers of one
    machine, or of several machines on a file system with working ``flock``), so the second worker
    waits and then finds the first one's folder. Without a working lock, the loser of the race gets
    ``FileExistsError`` from ``atomic_directory``; it then uses the winner's folder.
    """
    from bench.data.datasets import ensure_dataset, is_folder_scene

    if is_folder_scene(scene):  # a user's dataset folder: nothing to synthesise
        return
    cache_dir = Path(cache_dir)
    with _file_lock(cache_dir / ".locks" / f"{scene}-{scale}.lock"):
        try:
            ensure_dataset(scene, scale, cache_dir, effects=effects)
        except FileExistsError:
            ensure_dataset(scene, scale, cache_dir, effects=effects)  # the winner's folder is there now: just returns it


def _worker_identity() -> tuple[str, str]:
    """(worker name, executor kind) of the current process."""
    if "distributed" in sys.modules:
        try:
            from distributed import get_worker

            w = get_worker()
            return str(w.name), "dask"
        except (ImportError, ValueError):
            pass
    return f"{socket.gethostname()}:{os.getpid()}", "local"


def execute_job(job: "Job", cache_dir: Path | None, attempt: int = 1, threads: int | None = None,
                slots_by_host: dict[str, int] | None = None,
                progress: Callable[[float, str], None] | None = None) -> dict[str, Any]:
    """Run one job on this worker and return its result row (never raises for a job's own error).

    ``cache_dir``: the dataset cache (None: this checkout's default). ``threads``: torch threads for
    this job; if None, this machine's cores divided by the job slots on this machine
    (``slots_by_host[hostname]``, else this worker's own thread count).
    """
    t0 = time.perf_counter()
    if cache_dir is None:
        from bench.data.datasets import DEFAULT_CACHE

        cache_dir = DEFAULT_CACHE
    name, kind = _worker_identity()
    if threads is None:
        slots = 1
        if kind == "dask":
            from urllib.parse import urlparse

            from distributed import get_worker

            w = get_worker()
            host = urlparse(w.address).hostname or ""
            slots = (slots_by_host or {}).get(host) or w.state.nthreads
        threads = threads_per_job(slots)
    set_job_threads(threads)

    from bench.execute import run_job  # imports torch / open3d: keep this module light for worker start-up

    try:
        prepare_dataset(job.plan.scene, job.plan.scale, cache_dir, job.plan.effects)
    except Exception as exc:  # bad recipe etc.: a failed row, like any other error of the job
        row = failure_row(job, type(exc).__name__, str(exc), traceback.format_exc())
    else:
        row = run_job(job, cache_dir, progress)
    from bench.mkl_dispatch import blas_path

    row.update(attempts=attempt, wall_seconds=time.perf_counter() - t0, worker_name=name, executor=kind,
               torch_threads=threads, blas=blas_path())
    return row


def lost_row(job: "Job", attempts: int, message: str, executor: str, detail: str = "") -> dict[str, Any]:
    """The failure row of a job whose worker died ``attempts`` times (retries exhausted)."""
    text = f"the worker running this job died {attempts} time(s) (retries exhausted): {message}"
    row = failure_row(job, WORKER_LOST, text, detail or text)
    row.update(attempts=attempts, wall_seconds=None, worker_name=None, executor=executor, torch_threads=None, blas=None,
               created=_dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"))
    return row
