"""Dask distributed: a real scheduler and workers, on one machine or a cluster.

    bench run --table ablation --executor dask --scheduler tcp://HOST:8786   # an existing cluster
    bench run --table ablation --executor dask --workers 2                    # a LocalCluster here

Each job is one Dask task (:func:`bench.executors.base.execute_job`, keyed
``bench-<job_id>-a<attempt>``); the client (this process) receives each row as its task finishes and
:func:`bench.runner.run_jobs` writes it atomically right away. Workers must run the same code
(the ``bench`` package installed from the same commit) and can reach the dataset cache (the default
``results/cache/datasets`` of their own checkout, or ``$BENCH_CACHE`` where a worker's environment sets
it, or the ``cache_dir`` given, e.g. on a shared file system); each synthesises missing datasets itself under a file lock.

Fault tolerance: when a worker dies mid-task, the scheduler first reschedules the task itself up to
its ``distributed.scheduler.allowed-failures`` (default 3) and then reports ``KilledWorker``; this
executor then resubmits the job under a new key, at most ``retries`` more times, then records a
``WorkerLost`` failure row. ``attempts`` in a row counts this executor's submissions (the scheduler's
own silent reschedules are not visible to the client). A task that errs otherwise (the job function
raised outside the job's own code) becomes a failure row with the worker's traceback, not retried.

Torch threads per job: cores of the worker's machine divided by the job slots (worker threads) the
scheduler reports on that host, so two single-threaded workers on a 2-core machine use one torch
thread each.
"""

from __future__ import annotations

import logging
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Iterator, Sequence
from urllib.parse import urlparse

from bench.executors.base import DEFAULT_RETRIES, Event, Executor, ProgressFactory, execute_job, lost_row
from bench.executors.lifeline import interrupts_ignored

if TYPE_CHECKING:
    from distributed import Client, Future

    from bench.jobs import Job


@dataclass
class DaskExecutor(Executor):
    """Jobs as tasks of a Dask distributed cluster.

    Args:
        scheduler: address of a running scheduler (``tcp://HOST:PORT``); None starts a
            ``LocalCluster`` of ``workers`` single-threaded worker processes on 127.0.0.1.
        workers: worker processes of the local cluster (ignored with ``scheduler``).
        retries: resubmissions of a job whose worker died, before a ``WorkerLost`` row.
        connect_timeout: seconds to wait for the scheduler.
        poll_seconds: how often the progress display asks the scheduler what is running.
    """

    scheduler: str | None = None
    workers: int = 2
    retries: int = DEFAULT_RETRIES
    connect_timeout: float = 30.0
    poll_seconds: float = 1.0
    task: Callable[..., dict[str, Any]] = field(default=execute_job, repr=False)  # tests inject faults here
    _client: "Client | None" = field(default=None, init=False, repr=False)
    _cluster: Any = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        if self.retries < 0:
            raise ValueError(f"retries must be >= 0, got {self.retries}")
        if self.scheduler is None and self.workers < 1:
            raise ValueError(f"workers must be >= 1, got {self.workers}")
        self.name = "dask"

    # ---------------------------------------------------------------------------------------- cluster

    @property
    def client(self) -> "Client":
        """The connected client (connecting, or starting the local cluster, on first use)."""
        if self._client is None:
            from distributed import Client, LocalCluster

            if self.scheduler is None:  # its routine warnings (a cancelled task, a worker killed at close) not on stderr
                with interrupts_ignored():  # the worker processes inherit it: Ctrl-C is bench's, which closes the cluster
                    self._cluster = LocalCluster(n_workers=self.workers, threads_per_worker=1, processes=True,
                                                 host="127.0.0.1", dashboard_address=None, silence_logs=logging.ERROR)
                self._client = Client(self._cluster, timeout=self.connect_timeout, set_as_default=False)
            else:
                self._client = Client(self.scheduler, timeout=self.connect_timeout, set_as_default=False)
        return self._client

    def _workers(self) -> dict[str, dict[str, Any]]:
        return self.client.scheduler_info(n_workers=-1).get("workers", {})

    def slots_by_host(self) -> dict[str, int]:
        """Worker threads (job slots) per host, as the scheduler reports them now."""
        out: dict[str, int] = {}
        for addr, info in self._workers().items():
            host = urlparse(addr).hostname or addr
            out[host] = out.get(host, 0) + int(info.get("nthreads", 1))
        return out

    @property
    def slots(self) -> int:
        if self._client is None and self.scheduler is None:
            return self.workers
        return sum(self.slots_by_host().values())

    def describe(self) -> str:
        where = self.scheduler or "local cluster"
        return f"dask {where}, {self.slots} slots"

    def close(self) -> None:
        if self._client is not None:
            self._client.close()
            self._client = None
        if self._cluster is not None:
            self._cluster.close()
            self._cluster = None

    # ---------------------------------------------------------------------------------------- jobs

    def _submit(self, job: "Job", cache_dir: Path | None, attempt: int, slots: dict[str, int]) -> "Future":
        return self.client.submit(self.task, job, cache_dir, attempt, None, slots,
                                  key=f"bench-{job.job_id}-a{attempt}", pure=False, retries=0)

    def run(self, jobs: Sequence["Job"], cache_dir: Path | None, progress_for: ProgressFactory | None = None) -> Iterator[Event]:
        from distributed import wait
        from distributed.scheduler import KilledWorker

        from bench.data.datasets import DEFAULT_CACHE
        from bench.jobs import failure_row

        if not jobs:
            return
        # the default cache is each worker's own checkout's; an explicit one is passed as is
        remote_cache = None if cache_dir is None or Path(cache_dir) == DEFAULT_CACHE else Path(cache_dir)
        slots = self.slots_by_host()
        pending: dict["Future", tuple["Job", int]] = {}
        for job in jobs:
            pending[self._submit(job, remote_cache, 1, slots)] = (job, 1)
        last_poll = 0.0
        try:
            while pending:
                try:
                    with self.client.as_current():  # wait() uses the current client: ours, not a global
                        finished = wait(list(pending), timeout=self.poll_seconds, return_when="FIRST_COMPLETED").done
                except TimeoutError:
                    finished = set()
                for fut in finished:
                    job, attempt = pending.pop(fut)
                    if fut.status == "finished":
                        yield Event("done", job, fut.result(), attempt=attempt)
                    elif fut.status == "error" and not isinstance(fut.exception(), KilledWorker):
                        exc = fut.exception()
                        tb = "".join(traceback.format_exception(type(exc), exc, fut.traceback()))
                        row = failure_row(job, type(exc).__name__, str(exc), tb)
                        row.update(attempts=attempt, executor="dask")
                        yield Event("done", job, row, attempt=attempt)
                    else:  # KilledWorker, or cancelled (scheduler restarted / lost the task)
                        reason = f"{type(fut.exception()).__name__}: {fut.exception()}" if fut.status == "error" else f"task {fut.status}"
                        if attempt <= self.retries:
                            slots = self.slots_by_host()
                            pending[self._submit(job, remote_cache, attempt + 1, slots)] = (job, attempt + 1)
                            yield Event("retry", job, message=f"worker died ({reason})", attempt=attempt + 1)
                        else:
                            yield Event("done", job, lost_row(job, attempt, reason, "dask"), attempt=attempt)
                    fut.release()
                now = time.monotonic()
                if now - last_poll >= self.poll_seconds:
                    last_poll = now
                    yield Event("status", running=self._running({f.key for f in pending}))
        finally:
            for fut in pending:
                fut.cancel()

    def _running(self, keys: set[Any]) -> int | None:
        """How many of ``keys`` the scheduler has assigned to a worker right now (None if unknown)."""
        try:
            processing = self.client.processing()
        except Exception:  # progress only: never fail a run over it
            return None
        return sum(1 for ks in processing.values() for k in ks if k in keys)
