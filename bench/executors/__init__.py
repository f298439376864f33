"""Executors: where the jobs of a table run (see :mod:`bench.executors.base` for the contract).

* ``local`` (default): this machine, ``--workers N`` at a time (:mod:`bench.executors.local`);
* ``dask``: a Dask distributed cluster, ``--scheduler tcp://HOST:PORT`` (:mod:`bench.executors.dask`);
  Slurm / PBS clusters through dask-jobqueue (recipe in ``docs/scale-out.md``).
"""

from __future__ import annotations

from bench.executors.base import DEFAULT_RETRIES, Event, Executor

EXECUTORS: tuple[str, ...] = ("local", "dask")


def make_executor(kind: str = "local", workers: int | None = None, scheduler: str | None = None,
                  retries: int = DEFAULT_RETRIES) -> Executor:
    """An executor by name. ``workers``: local processes (default 1; for ``dask`` without a
    ``scheduler``, the size of the local cluster, default 2). ``scheduler`` is for ``dask`` only."""
    if kind == "local":
        if scheduler is not None:
            raise ValueError("--scheduler is for --executor dask")
        from bench.executors.local import LocalExecutor

        return LocalExecutor(workers=workers or 1, retries=retries)
    if kind == "dask":
        from bench.executors.dask import DaskExecutor

        return DaskExecutor(scheduler=scheduler, workers=workers or 2, retries=retries)
    raise ValueError(f"unknown executor {kind!r} (known: {list(EXECUTORS)})")


__all__ = ["DEFAULT_RETRIES", "EXECUTORS", "Event", "Executor", "make_executor"]
