"""A user's ``bench`` command ends with one line, never a traceback: Ctrl-C at any moment (the whole process
group gets SIGINT, as from a terminal), a closed output pipe, an ``--out`` that is a file."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from cluster_helpers import kill_group

from bench.cli import main

REPO = Path(__file__).resolve().parents[2]
# Exit statuses of "stopped by Ctrl-C" as a shell sees them (both give $? = 130): bench's own 130, or death by SIGINT
# itself. Measured: a SIGINT 1 s after the start (planning) ends about one time in six as death by SIGINT *after*
# bench has printed its line; the mechanism is not identified, the user sees the same line and status.
INTERRUPTED = (130, -signal.SIGINT)
MARKER_WAIT_S = 300  # a run that never prints its marker is killed then (the test fails on the missing marker, never hangs)


def _bench(*args: str, **kw) -> subprocess.Popen:
    """``bench ARGS`` as the console script runs it (``main()`` without argv), in its own process group, with
    SIGINT's default disposition, as from a terminal (a test run in the background inherits it ignored)."""
    return subprocess.Popen([sys.executable, "-m", "bench.cli", *args], cwd=REPO, text=True, start_new_session=True,
                            env={**os.environ, "PYTHONPATH": str(REPO)},
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL), **kw)


def _interrupt_when(out: Path, marker: str | None, delay_s: float, executor: str) -> tuple[int, str, str]:
    """Run ``bench run`` (the ablation table at tiny scale with 200 seeds, every job anew) on ``executor`` into
    ``out``; SIGINT its process group ``delay_s`` after ``marker`` appears on its stdout (None: after its start);
    its (exit status, stdout, stderr)."""
    p = _bench("run", "--table", "ablation", "--scale", "tiny", "--seeds", *map(str, range(200)), "--executor", executor,
               "--workers", "2", "--force", "--out", str(out), stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    assert p.stdout is not None and p.stderr is not None
    lines = []
    watchdog = threading.Timer(MARKER_WAIT_S, kill_group, args=(p,))
    watchdog.start()
    try:
        if marker is None:
            time.sleep(delay_s)
            os.killpg(p.pid, signal.SIGINT)
        for line in [] if marker is None else p.stdout:
            lines.append(line)
            if marker in line:
                time.sleep(delay_s)
                os.killpg(p.pid, signal.SIGINT)
                break
        rest, err = p.communicate(timeout=120)
    finally:
        watchdog.cancel()
        kill_group(p)
    return p.returncode, "".join(lines) + rest, err


@pytest.mark.slow
@pytest.mark.parametrize("marker,delay_s,executor", [
    (None, 1.0, "local"),  # importing, parsing the command line or planning 1200 jobs
    ("job(s) to run", 0.0, "local"),  # the fork server is importing torch
    ("job(s) to run", 1.0, "local"),  # ... the workers are forked and unpickle their pool's queues
    ("job(s) to run", 2.0, "local"),
    ("started", 3.0, "local"),  # jobs are training
    ("job(s) to run", 10.0, "dask"),  # a local Dask cluster's workers are training
], ids=["while-starting", "as-fork-server-starts", "as-workers-start", "as-workers-start-later", "mid-run", "dask-mid-run"])
def test_ctrl_c_at_any_moment_ends_with_one_line_and_no_empty_folder(tmp_path: Path, marker: str, delay_s: float, executor: str):
    code, out, err = _interrupt_when(tmp_path / "runs", marker, delay_s, executor)
    assert marker is None or marker in out, out
    assert code in INTERRUPTED, err
    assert err.strip().splitlines() == ["interrupted (Ctrl-C): running jobs stopped; finished results are kept"], err
    assert not (tmp_path / "runs").exists()  # nothing finished: no empty output folder is left behind


@pytest.mark.slow
def test_ctrl_c_stops_a_bench_started_by_a_program_that_ran_a_pool(tmp_path: Path, monkeypatch):
    """A program (or a test session) that has run a pool in-process carries the fork server's lifeline variable
    naming itself; a ``bench`` it starts inherits it and must still stop on Ctrl-C (only a fork server arms)."""
    from bench.executors.lifeline import ENV

    monkeypatch.setenv(ENV, str(os.getpid()))  # as ``mark_parent()`` leaves it in a process that started a pool
    code, out, err = _interrupt_when(tmp_path / "runs", "job(s) to run", 1.0, "local")
    assert code in INTERRUPTED, err
    assert err.strip().splitlines() == ["interrupted (Ctrl-C): running jobs stopped; finished results are kept"], err


@pytest.mark.slow
def test_a_closed_pipe_ends_quietly():
    """``bench list | head``: the reader is gone before bench writes."""
    p = _bench("list", stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    assert p.stdout is not None
    p.stdout.close()
    _, err = p.communicate(timeout=300)
    assert p.returncode == 141 and err == "", err


def test_fit_into_an_existing_file_says_so(tmp_path: Path, capsys):
    target = tmp_path / "result.txt"
    target.write_text("mine")
    assert main(["fit", "monosdf", str(tmp_path), "--scale", "tiny", "--out", str(target)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"error: {target}: is a file, not a folder (--out names the output folder)"]
    assert target.read_text() == "mine"
