"""Soak (nightly): many tiny jobs through a real Dask cluster while it is disturbed, then resumed.

A scheduler and two single-threaded workers run ``bench run`` of the ablation table's oracle row at the tiny
scale with ``BENCH_SOAK_JOBS`` seeds (default 200) twice: once undisturbed, once while a worker is killed
(SIGKILL, a fresh one started in its place) three times and the ``bench`` process itself once, at random points
of the run (``BENCH_SOAK_SEED``), the killed run resumed by running the same command again. Every planned job
must be stored exactly once and ok, and the table (``ablation.csv``: every cell's mean, std and counts) must be
byte-identical to the undisturbed run's. Long (~2 x 200 jobs): run with ``pytest -m nightly``; a reduced check:
``BENCH_SOAK_JOBS=12 pytest -m nightly tests/harness/test_soak.py``.
"""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import time
from pathlib import Path

import pytest
from cluster_helpers import REPO, kill_group, start, wait_for

from bench.pipeline import plan_table
from bench.table_spec import load_table_spec

pytestmark = pytest.mark.nightly

JOBS = int(os.environ.get("BENCH_SOAK_JOBS", "200"))
SEED = int(os.environ.get("BENCH_SOAK_SEED", "0"))
ORACLE = "Oracle: TSDF of GT depth (upper bound)"


def _spec(tmp_path: Path) -> Path:
    text = (REPO / "configs" / "tables" / "ablation.yaml").read_text()
    text = text.replace("seeds: {tiny: [0], small: [0, 1, 2]}", f"seeds: {{tiny: {list(range(JOBS))}, small: [0, 1, 2]}}")
    path = tmp_path / "spec" / "ablation.yaml"
    path.parent.mkdir()
    path.write_text(text)
    return path


class Cluster:
    """A scheduler and two named single-threaded workers, each in its own session (killed by pid)."""

    def __init__(self, tmp_path: Path, env: dict[str, str]) -> None:
        self.tmp, self.env, self.count = tmp_path, env, 0
        self.file = tmp_path / "scheduler.json"
        self.scheduler = start(["distributed.cli.dask_scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                                "--scheduler-file", str(self.file)], tmp_path / "scheduler.log", env)
        wait_for(lambda: self.file.exists() and self.file.stat().st_size > 0, 60, "the scheduler file")
        self.address = json.loads(self.file.read_text())["address"]
        self.workers: list[subprocess.Popen] = []
        for _ in range(2):
            self.add_worker()

    def add_worker(self) -> None:
        self.count += 1
        name = f"w{self.count}"
        self.workers.append(start(["distributed.cli.dask_worker", "--scheduler-file", str(self.file), "--host", "127.0.0.1",
                                   "--nthreads", "1", "--no-nanny", "--name", name, "--no-dashboard", "--death-timeout", "60",
                                   "--local-directory", str(self.tmp / f"dask-{name}")], self.tmp / f"{name}.log", self.env))

    def kill_worker(self, rng: random.Random) -> None:
        """SIGKILL one live worker at random and start a fresh one in its place."""
        victim = rng.choice([w for w in self.workers if w.poll() is None])
        os.kill(victim.pid, signal.SIGKILL)
        victim.wait(timeout=30)
        self.add_worker()

    def close(self) -> None:
        for proc in [*self.workers, self.scheduler]:
            kill_group(proc)


def _bench_run(cluster: Cluster, spec: Path, out: Path, log: Path) -> subprocess.Popen:
    return start(["bench.cli", "run", "--table", str(spec), "--scale", "tiny", "--rows", ORACLE, "--executor", "dask",
                  "--scheduler", cluster.address, "--out", str(out), "--quiet", "--no-artifacts"], log, cluster.env)


def _stored(out: Path) -> int:
    return len(list((out / "tiny" / "jobs").glob("*.json"))) if (out / "tiny" / "jobs").is_dir() else 0


def test_killed_workers_and_a_killed_bench_resume_to_the_undisturbed_table(tmp_path: Path):
    spec = _spec(tmp_path)
    env = {**os.environ, "PYTHONPATH": str(REPO), "OMP_NUM_THREADS": "1",
           "DASK_DISTRIBUTED__SCHEDULER__WORKER_SATURATION": "1.0"}
    deadline = 120 + 15 * JOBS  # seconds per run (an oracle job takes ~5 s on one thread)
    rng = random.Random(SEED)
    events = sorted([(rng.uniform(0.05, 0.9), "worker") for _ in range(3)] + [(rng.uniform(0.2, 0.7), "bench")])
    cluster = Cluster(tmp_path, env)
    runs: list[subprocess.Popen] = []
    try:
        calm = _bench_run(cluster, spec, tmp_path / "calm", tmp_path / "calm.log")
        runs.append(calm)
        assert calm.wait(timeout=deadline) == 0, (tmp_path / "calm.log").read_text()[-3000:]

        out = tmp_path / "disturbed"
        run = _bench_run(cluster, spec, out, tmp_path / "disturbed-0.log")
        runs.append(run)
        done_events, t0 = [], time.monotonic()
        while events:
            at, kind = events[0]
            wait_for(lambda: _stored(out) >= at * JOBS or run.poll() is not None, deadline, f"{at:.0%} of the jobs")
            assert run.poll() is None, f"the run ended before the {kind} kill at {at:.0%}"
            events.pop(0)
            if kind == "worker":
                cluster.kill_worker(rng)
            else:  # the bench process alone (SIGKILL: no cleanup), then the same command again: the resume
                os.kill(run.pid, signal.SIGKILL)
                run.wait(timeout=30)
                run = _bench_run(cluster, spec, out, tmp_path / f"disturbed-{len(runs)}.log")
                runs.append(run)
            done_events.append(f"{kind} at {_stored(out)}/{JOBS}")
        assert run.wait(timeout=deadline) == 0, (tmp_path / f"disturbed-{len(runs) - 1}.log").read_text()[-3000:]
        print(f"soak: {JOBS} jobs, {', '.join(done_events)}; disturbed run {time.monotonic() - t0:.0f} s")
    finally:
        for proc in runs:
            kill_group(proc)
        cluster.close()

    planned = {j.job_id for j in plan_table(load_table_spec(spec), "tiny", [ORACLE]).jobs}
    rows = [json.loads(p.read_text()) for p in (out / "tiny" / "jobs").glob("*.json")]
    assert sorted(r["job_id"] for r in rows) == sorted(planned) and len(planned) == JOBS  # every job once
    assert all(r["status"] == "ok" for r in rows), [r.get("error") for r in rows if r["status"] != "ok"]
    assert not [p for p in (out / "tiny").rglob("*") if p.name.startswith(".")]  # no temporary left
    assert (out / "tiny" / "ablation.csv").read_bytes() == (tmp_path / "calm" / "tiny" / "ablation.csv").read_bytes()
