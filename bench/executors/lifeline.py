"""Every process a ``bench`` command starts dies with it, however it dies (``kill -9`` included).

The process tree of a pool run: ``bench`` -> fork server -> workers, and ``bench`` -> resource tracker.
Linux's ``PR_SET_PDEATHSIG`` makes the kernel signal a process when its parent dies, one level at a
time, so each level arms it for itself:

* the fork server: :func:`mark_parent` (called by ``bench`` before it starts a pool) puts bench's pid in
  the environment, and the fork server imports this module through its preload list
  (:data:`FORKSERVER_PRELOAD`); the import arms the signal in the process whose parent is that pid
  (and in no other: ``bench`` itself, started by a shell or ``nohup``, must not die with its shell);
* the workers (their parent is the fork server): :func:`exit_with_parent` in the pool initializer.

The fork server and the workers ignore SIGINT (a terminal's Ctrl-C reaches the whole process group):
``bench`` catches it and terminates them, and none of them prints a ``KeyboardInterrupt`` traceback. A Dask
``LocalCluster``'s worker processes are started under :func:`interrupts_ignored` for the same reason.

When ``bench`` dies the fork server is killed, which kills the workers; the resource tracker then reads
EOF from its last writer and exits by itself. No-op outside Linux.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
import traceback
from types import TracebackType
from typing import Iterator

ENV = "BENCH_LIFELINE_PID"
FORKSERVER_PRELOAD = [__name__]


def exit_with_parent(sig: int = signal.SIGKILL) -> None:
    """Ask the kernel to send ``sig`` to this process when its parent dies; exit now if the parent is
    already gone (it died before the signal was armed)."""
    if not sys.platform.startswith("linux"):
        return
    import ctypes

    parent = os.getppid()
    try:
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, int(sig))  # PR_SET_PDEATHSIG
    except OSError:
        return
    if os.getppid() != parent or parent == 1:
        os._exit(1)


def ignore_interrupts() -> None:
    """Ignore SIGINT in this (worker) process: Ctrl-C is ``bench``'s to handle; it terminates its workers."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


@contextlib.contextmanager
def interrupts_ignored() -> Iterator[None]:
    """Ignore SIGINT in this process while the block starts worker processes, which inherit the ignored
    disposition (a handler would not survive their ``exec``); restored after. The main thread only."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def mark_parent() -> None:
    """Record this process as the one whose death must take the fork server (and so the pool) with it."""
    os.environ[ENV] = str(os.getpid())


def _quiet_when_the_pool_is_gone(exc_type: type[BaseException], exc: BaseException, tb: TracebackType | None) -> None:
    """``sys.excepthook`` of the fork server's children: a worker forked while ``bench`` shuts its pool down (Ctrl-C as
    the workers start) finds the pool's semaphore already removed (``FileNotFoundError`` while unpickling it) and
    exits without a traceback; any other error is printed as usual."""
    if issubclass(exc_type, FileNotFoundError) and any(f.f_code.co_name == "__setstate__" for f, _ in traceback.walk_tb(tb)):
        return
    sys.__excepthook__(exc_type, exc, tb)


def _is_fork_server() -> bool:
    """True in a multiprocessing fork server (started as ``python -c "from multiprocessing.forkserver import main;
    ..."``, it imports this module as its preload). Another process whose parent set the variable, e.g. a ``bench``
    command started by a program that has run a pool itself, inherits it but must not arm: it would ignore Ctrl-C."""
    return sys.argv[:1] == ["-c"] and "multiprocessing.forkserver" in sys.modules


if os.environ.get(ENV) == str(os.getppid()) and _is_fork_server():  # imported by the fork server bench started: arm it
    exit_with_parent()
    # Ctrl-C reaches the whole process group; bench stops the workers itself. The fork server ignores SIGINT once
    # its preload is imported: ignore it from here, so a Ctrl-C while it imports torch prints no traceback.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    sys.excepthook = _quiet_when_the_pool_is_gone  # inherited by the workers it forks
