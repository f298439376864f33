"""The default executor: this machine, ``--workers N`` jobs at a time.

``workers=1`` runs the jobs one after another in this process (exactly the harness's behaviour
before executors existed, with the per-job progress bar). ``workers > 1`` uses a
:class:`concurrent.futures.ProcessPoolExecutor` with the ``spawn`` start method (torch and open3d are
not fork-safe); each worker process limits torch to ``cores // workers`` threads before any work.

Fault tolerance: at most ``workers`` jobs are in flight, so every submitted job is running. If a
worker process dies (killed, segfault, out of memory), the standard library pool is broken and
terminates all its workers, and it cannot say which job's process died. So the jobs that were in
flight are rerun one at a time in a fresh pool, uncharged; a job whose worker dies while it runs
alone is charged one attempt and resubmitted, at most ``retries`` more times, then recorded as a
``WorkerLost`` failure row. Innocent bystanders of a crash therefore never use up their retries. A
worker can also die between two submissions (its job still in flight, another just finished): the
next ``submit`` then finds the pool broken; that job has not started, so it goes back to the front of
its queue, uncharged, and the in-flight futures report the break as above.
"""

from __future__ import annotations

import multiprocessing
from collections import deque
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterator, Sequence

from bench.executors.base import DEFAULT_RETRIES, Event, Executor, ProgressFactory, execute_job, lost_row, set_job_threads, threads_per_job
from bench.executors.lifeline import FORKSERVER_PRELOAD, exit_with_parent, ignore_interrupts, mark_parent
from bench.jobs import Job

START_METHOD = "forkserver"
PRELOAD = [*FORKSERVER_PRELOAD, "bench.execute"]  # imported once by the fork server (torch, open3d, ...): workers start in ms;
# the lifeline first: the fork server dies with bench (bench.executors.lifeline)


def _init_worker(threads: int) -> None:
    exit_with_parent()
    ignore_interrupts()
    set_job_threads(threads)


@dataclass
class LocalExecutor(Executor):
    """``workers`` jobs at a time on this machine (1: in this process; more: a spawn process pool)."""

    workers: int = 1
    retries: int = DEFAULT_RETRIES
    start_method: str = START_METHOD
    task: Callable[..., dict[str, Any]] = field(default=execute_job, repr=False)  # tests inject faults here
    _pool: ProcessPoolExecutor | None = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        if self.workers < 1:
            raise ValueError(f"workers must be >= 1, got {self.workers}")
        if self.retries < 0:
            raise ValueError(f"retries must be >= 0, got {self.retries}")
        self.name = "local"

    @property
    def slots(self) -> int:
        return self.workers

    @property
    def threads(self) -> int:
        """Torch threads per job: this machine's cores divided by the workers."""
        return threads_per_job(self.workers)

    @property
    def planned_threads(self) -> int | None:
        return self.threads

    def run(self, jobs: Sequence["Job"], cache_dir: Path, progress_for: ProgressFactory | None = None) -> Iterator[Event]:
        if self.workers == 1:
            yield from self._run_here(jobs, cache_dir, progress_for)
        else:
            yield from self._run_pool(jobs, cache_dir)

    def _run_here(self, jobs: Sequence["Job"], cache_dir: Path, progress_for: ProgressFactory | None) -> Iterator[Event]:
        for job in jobs:
            yield Event("started", job)
            progress = progress_for(job) if progress_for else None
            yield Event("done", job, self.task(job, cache_dir, 1, self.threads, progress=progress))

    def _new_pool(self) -> ProcessPoolExecutor:
        ctx = multiprocessing.get_context(self.start_method)
        mark_parent()
        if self.start_method == "forkserver":
            ctx.set_forkserver_preload(PRELOAD)
        return ProcessPoolExecutor(max_workers=self.workers, mp_context=ctx, initializer=_init_worker,
                                   initargs=(self.threads,))

    def _run_pool(self, jobs: Sequence["Job"], cache_dir: Path) -> Iterator[Event]:
        queue: deque[tuple["Job", int]] = deque((j, 1) for j in jobs)
        isolate: deque[tuple["Job", int]] = deque()  # in flight when the pool broke: rerun one at a time
        inflight: dict[Future, tuple["Job", int]] = {}
        try:
            while queue or isolate or inflight:
                if self._pool is None:
                    self._pool = self._new_pool()
                while (isolate and not inflight) or (not isolate and queue and len(inflight) < self.workers):
                    source = isolate or queue
                    job, attempt = source.popleft()
                    try:
                        future = self._pool.submit(self.task, job, cache_dir, attempt, self.threads)
                    except BrokenProcessPool:  # a worker died after the last wait(): this job never started
                        source.appendleft((job, attempt))
                        if not inflight:  # no in-flight future will report the break: start a fresh pool
                            self._discard_pool()
                        break  # else the in-flight futures fail with BrokenProcessPool below
                    inflight[future] = (job, attempt)
                    yield Event("started", job, attempt=attempt)
                if self._pool is None:
                    continue
                finished, _ = wait(list(inflight), timeout=1.0, return_when=FIRST_COMPLETED)
                victims: list[tuple["Job", int]] = []
                for fut in finished:
                    job, attempt = inflight.pop(fut)
                    exc = fut.exception()
                    if exc is None:
                        yield Event("done", job, fut.result(), attempt=attempt)
                    elif isinstance(exc, BrokenProcessPool):
                        victims.append((job, attempt))
                    else:  # execute_job does not raise for a job's own errors: this is e.g. unpicklable output
                        from bench.jobs import failure_row

                        row = failure_row(job, type(exc).__name__, str(exc), f"{type(exc).__name__}: {exc}")
                        row.update(attempts=attempt, executor="local")
                        yield Event("done", job, row, attempt=attempt)
                if victims:  # a worker process died; the pool killed the others and is unusable
                    self._discard_pool()
                    victims += list(inflight.values())
                    inflight.clear()
                    if len(victims) == 1:  # it ran alone: it is the one that died
                        yield from self._lost(*victims[0], "worker process died (BrokenProcessPool)", queue)
                    else:  # cannot tell which one died: rerun each alone, uncharged
                        for job, attempt in victims:
                            isolate.append((job, attempt))
                            yield Event("retry", job, message="a worker process died while this job was in flight; "
                                        "rerunning it alone to find the culprit", attempt=attempt)
                elif not finished:
                    yield Event("status", running=len(inflight))
        finally:
            if inflight:  # left early (Ctrl-C, SIGTERM, an error in the consumer): stop the running jobs
                self._terminate_workers()

    def _lost(self, job: "Job", attempt: int, message: str, queue: deque) -> Iterator[Event]:
        if attempt <= self.retries:
            queue.append((job, attempt + 1))
            yield Event("retry", job, message=message, attempt=attempt + 1)
        else:
            yield Event("done", job, lost_row(job, attempt, message, "local"), attempt=attempt)

    def _terminate_workers(self) -> None:
        """Kill the pool's worker processes now (not after their jobs) and drop the pool."""
        if self._pool is not None:
            for proc in list((getattr(self._pool, "_processes", None) or {}).values()):
                proc.terminate()
            self._discard_pool()

    def _discard_pool(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=False, cancel_futures=True)
            self._pool = None

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None
