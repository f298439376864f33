"""Helpers of the tests that start real processes (a Dask scheduler and workers, ``bench`` commands): bounded
waits and processes in their own session, so a test can kill each one and its children by pid."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any, Callable

REPO = Path(__file__).resolve().parents[2]


def wait_for(cond: Callable[[], Any], timeout: float, what: str, poll: float = 0.05) -> Any:
    """``cond()``'s first truthy value, polled every ``poll`` s; TimeoutError naming ``what`` after ``timeout`` s."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        value = cond()
        if value:
            return value
        time.sleep(poll)
    raise TimeoutError(f"timed out after {timeout:.0f} s waiting for {what}")


def start(args: list[str], log: Path, env: dict[str, str]) -> subprocess.Popen:
    """``python -m ARGS`` from the repository, output to ``log``, in its own session."""
    return subprocess.Popen([sys.executable, "-m", *args], stdout=log.open("wb"), stderr=subprocess.STDOUT,
                            env=env, start_new_session=True, cwd=str(REPO))


def kill_group(proc: subprocess.Popen) -> None:
    """SIGKILL ``proc``'s session (it leads one: :func:`start`) and reap it."""
    if proc.poll() is None:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        proc.wait(timeout=30)
