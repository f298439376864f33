"""A real Dask cluster: a scheduler and two workers as separate processes on 127.0.0.1 run a tiny table
(the oracle row of the ablation table, three seeds); one worker is killed (SIGKILL) while it runs a
job. Every expected row must be stored exactly once, ok, with the metrics of a local run, and the
interrupted job must show a second attempt on the surviving worker.

Bounded in time (every wait has a deadline); all processes are started in their own session and
killed by pid in ``finally``.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from cluster_helpers import kill_group, start, wait_for

from bench.executors.dask import DaskExecutor
from bench.executors.local import LocalExecutor
from bench.pipeline import plan_jobs
from bench.report import build_table
from bench.results_io import collect_results
from bench.runner import plan_index, resolve_jobs, run_jobs
from bench.table_spec import load_table_spec
from methods.registry import available_methods

pytestmark = pytest.mark.slow  # end to end (pyproject's `slow` marker; skipped by the fast loop -m 'not slow')

REPO = Path(__file__).resolve().parents[2]
SEEDS = [0, 1, 2]
DEADLINE = 240.0  # seconds for the whole distributed run (typically ~30 s)
RTOL, ATOL = 1e-6, 1e-9  # determinism tolerance: same job, same machine, other process / thread count


def _tiny_table(tmp_path: Path):
    """The ablation spec with three seeds at the tiny scale (a tiny table with several jobs)."""
    text = (REPO / "configs" / "tables" / "ablation.yaml").read_text()
    text = text.replace("seeds: {tiny: [0], small: [0, 1, 2]}", f"seeds: {{tiny: {SEEDS}, small: [0, 1, 2]}}")
    assert str(SEEDS) in text
    path = tmp_path / "spec" / "ablation.yaml"
    path.parent.mkdir()
    path.write_text(text)
    spec = load_table_spec(path)
    oracle = [p for p in plan_jobs(spec, "tiny") if p.row.startswith("Oracle")]  # the cheap row: this tests the engine
    jobs, _pending = resolve_jobs(oracle)
    assert len(jobs) == len(SEEDS)
    return spec, jobs


def test_cluster_survives_a_killed_worker_and_matches_local(tmp_path):
    from distributed import Client

    spec, jobs = _tiny_table(tmp_path)
    env = {**os.environ,
           # the scheduler reports a dead worker's task at once, so the harness's bounded retry is
           # what recovers it (and records attempts=2); one task per single-threaded worker at a time
           "DASK_DISTRIBUTED__SCHEDULER__ALLOWED_FAILURES": "0",
           "DASK_DISTRIBUTED__SCHEDULER__WORKER_SATURATION": "1.0",
           "OMP_NUM_THREADS": "1"}
    sched_file = tmp_path / "scheduler.json"
    procs: dict[str, subprocess.Popen] = {}
    monitor = None
    try:
        procs["scheduler"] = start(["distributed.cli.dask_scheduler", "--host", "127.0.0.1", "--port", "0",
                                     "--no-dashboard", "--scheduler-file", str(sched_file)],
                                    tmp_path / "scheduler.log", env)
        wait_for(lambda: sched_file.exists() and sched_file.stat().st_size > 0, 60, "the scheduler file")
        for name in ("w1", "w2"):
            procs[name] = start(["distributed.cli.dask_worker", "--scheduler-file", str(sched_file),
                                  "--host", "127.0.0.1", "--nthreads", "1", "--no-nanny", "--name", name,
                                  "--no-dashboard", "--death-timeout", "60",
                                  "--local-directory", str(tmp_path / f"dask-{name}")],
                                 tmp_path / f"{name}.log", env)
        address = json.loads(sched_file.read_text())["address"]
        assert address.startswith("tcp://127.0.0.1:")
        monitor = Client(address, timeout=60, set_as_default=False)
        monitor.wait_for_workers(2, timeout=90)

        out, cache = tmp_path / "dask_run", tmp_path / "cache"
        result: dict = {}

        def client_run():
            try:
                with DaskExecutor(scheduler=address, retries=2, poll_seconds=0.2) as ex:
                    result["rows"] = run_jobs(jobs, out, cache_dir=cache, show_progress=False, executor=ex)
            except BaseException as exc:  # surfaced in the test thread below
                result["error"] = exc

        runner = threading.Thread(target=client_run, daemon=True)
        t0 = time.monotonic()
        runner.start()

        def w1_busy():
            info = monitor.scheduler_info(n_workers=-1)["workers"]
            addr = next((a for a, w in info.items() if w.get("name") == "w1"), None)
            return addr is not None and bool(monitor.processing().get(addr))

        wait_for(w1_busy, 120, "worker w1 to start a job")
        time.sleep(0.5)  # not synchronisation: let the job get past its start (it runs for seconds)
        os.kill(procs["w1"].pid, signal.SIGKILL)
        procs["w1"].wait(timeout=30)

        runner.join(timeout=DEADLINE)
        assert not runner.is_alive(), f"distributed run did not finish in {DEADLINE} s"
        if "error" in result:
            raise result["error"]
        wall = time.monotonic() - t0

        # every expected row, exactly once, ok
        files = sorted((out / "jobs").glob("*.json"))
        stored = [json.loads(p.read_text()) for p in files]
        assert sorted(r["job_id"] for r in stored) == sorted(j.job_id for j in jobs)
        assert all(r["status"] == "ok" for r in stored), [r.get("error") for r in stored]
        assert not [p for p in (out / "jobs").iterdir() if p.name.startswith(".")]
        retried = [r for r in stored if r["attempts"] > 1]
        assert retried, "the killed worker's job was not retried"
        assert all(r["worker_name"] == "w2" for r in retried)
        assert all(r["executor"] == "dask" and r["wall_seconds"] > 0 for r in stored)
        # torch threads = cores // job slots on the host at submission: 2 workers share the cores; a job
        # resubmitted after w1 died may get the whole machine
        assert all(1 <= r["torch_threads"] <= max(1, os.cpu_count() or 1) for r in stored)
        assert any(r["torch_threads"] == max(1, (os.cpu_count() or 1) // 2) for r in stored if r["attempts"] == 1)
        report = build_table(spec, collect_results(out), "tiny", available_methods(), plans=plan_index(jobs))
        oracle = spec.rows[0].label
        assert all(c.status == "complete" and c.n == len(SEEDS) for (row, _, _), c in report.cells.items()
                   if row == oracle and c.status != "not_reported")

        # same metrics as a local run of the same jobs
        local = {r["job_id"]: r for r in run_jobs(jobs, tmp_path / "local_run", cache_dir=cache,
                                                   show_progress=False, executor=LocalExecutor(workers=1))}
        for r in stored:
            ref = local[r["job_id"]]["metrics"]
            assert set(r["metrics"]) == set(ref)
            for k, v in ref.items():
                assert np.isclose(r["metrics"][k], v, rtol=RTOL, atol=ATOL), (k, r["metrics"][k], v)
        print(f"distributed run: {len(jobs)} jobs in {wall:.1f} s, retried: {[r['seed'] for r in retried]}")
    finally:
        if monitor is not None:
            monitor.close()
        for proc in procs.values():  # by pid: each process leads its own session
            kill_group(proc)
