"""Executors (fast): the event contract, bounded retries of dead workers, failure rows, rows written as
they arrive, reruns, thread shares and the shared dataset cache race. Faults are injected through the
executors' ``task`` hook with tiny fake jobs (no reconstruction), so these run in seconds; the real
multi-process Dask cluster is exercised in ``test_dask_cluster.py``."""

from __future__ import annotations

import json
import os
import signal
import sys
import time
from pathlib import Path

import pytest

from bench.cli import main
from bench.executors import make_executor
from bench.executors.base import WORKER_LOST, prepare_dataset, threads_per_job
from bench.executors.dask import DaskExecutor
from bench.executors.local import LocalExecutor
from bench.jobs import Job, JobPlan, failure_row, result_path, row_head
from bench.runner import needs_run, run_jobs


def _job(i: int, tag: str = "") -> Job:
    plan = JobPlan("t", "oracle", "oracle_tsdf", {}, "scannet", "scannet", "scannet", "scannet_like_tiny", i, "tiny")
    return Job(plan, {"tag": tag}, f"{tag:0<8.8}{i:08d}")


def fake_task(job: Job, cache_dir, attempt: int = 1, threads=None, *args, **kwargs) -> dict:
    """A fake job. ``config.tag``: "crash1" kills its worker on attempt 1, "crash" on every attempt,
    "crashlate" after 0.5 s, "raise" raises (an error outside the job's own code), anything else
    returns an ok row."""
    tag = job.config["tag"]
    if tag == "crashlate":
        time.sleep(0.5)
        os.kill(os.getpid(), signal.SIGKILL)
    if tag == "crash" or (tag == "crash1" and attempt == 1):
        os.kill(os.getpid(), signal.SIGKILL)
    if tag == "raise":
        raise RuntimeError("boom outside the job")
    row = row_head(job)
    row.update(status="ok", error=None, metrics={"fscore": 0.5 + job.plan.seed / 100}, curve=[], iterations=1,
               timings={"total": 0.0}, attempts=attempt, worker_name=f"pid{os.getpid()}", wall_seconds=0.0)
    return row


def _events(executor, jobs, tmp_path):
    with executor:
        return list(executor.run(jobs, tmp_path / "cache"))


def test_threads_per_job_share_the_cores():
    assert threads_per_job(2, cores=2) == 1
    assert threads_per_job(1, cores=2) == 2
    assert threads_per_job(4, cores=2) == 1  # never zero
    assert threads_per_job(3, cores=8) == 2


def test_local_in_process_one_done_per_job(tmp_path):
    jobs = [_job(i, "ok") for i in range(3)]
    events = _events(LocalExecutor(workers=1, task=fake_task), jobs, tmp_path)
    done = [e for e in events if e.kind == "done"]
    assert [e.job.job_id for e in done] == [j.job_id for j in jobs]
    assert all(e.row["status"] == "ok" for e in done)


@pytest.mark.slow
def test_local_pool_retries_a_dead_worker_then_succeeds(tmp_path):
    jobs = [_job(0, "crash1"), _job(1, "ok"), _job(2, "ok")]
    events = _events(LocalExecutor(workers=2, retries=2, task=fake_task), jobs, tmp_path)
    done = {e.job.job_id: e.row for e in events if e.kind == "done"}
    assert set(done) == {j.job_id for j in jobs}  # exactly one final row per job
    assert len([e for e in events if e.kind == "done"]) == 3
    assert all(r["status"] == "ok" for r in done.values())
    assert done[jobs[0].job_id]["attempts"] == 2
    assert any(e.kind == "retry" and e.job.job_id == jobs[0].job_id for e in events)


@pytest.mark.slow
def test_local_pool_bounded_retries_then_a_clear_failure_row(tmp_path):
    jobs = [_job(0, "crash")]
    events = _events(LocalExecutor(workers=2, retries=1, task=fake_task), jobs, tmp_path)
    done = [e for e in events if e.kind == "done"]
    assert len(done) == 1 and sum(e.kind == "retry" for e in events) == 1  # ran alone: charged at once
    row = done[0].row
    assert row["status"] == "failed" and row["error"]["type"] == WORKER_LOST and row["attempts"] == 2
    assert "died 2 time(s)" in row["error"]["message"]


@pytest.mark.slow
def test_local_pool_a_worker_dying_between_submissions_loses_no_job(tmp_path):
    """Job 1 finishes, and while the consumer handles its row job 0's worker dies: the next submit
    finds the pool broken (CI failure, stop 45). Job 2 had not started: it must run, uncharged."""
    jobs = [_job(0, "crashlate"), _job(1, "ok"), _job(2, "ok")]
    events = []
    with LocalExecutor(workers=2, retries=0, task=fake_task) as ex:
        for event in ex.run(jobs, tmp_path / "cache"):
            events.append(event)
            if event.kind == "done" and event.job.job_id == jobs[1].job_id:
                time.sleep(2.0)  # job 0's worker dies meanwhile
    done = {e.job.job_id: e.row for e in events if e.kind == "done"}
    assert len([e for e in events if e.kind == "done"]) == 3 and set(done) == {j.job_id for j in jobs}
    assert done[jobs[0].job_id]["error"]["type"] == WORKER_LOST
    assert done[jobs[2].job_id]["status"] == "ok" and done[jobs[2].job_id]["attempts"] == 1


@pytest.mark.slow
def test_run_jobs_writes_every_row_and_rerun_retries_only_lost_jobs(tmp_path):
    jobs = [_job(0, "crash"), _job(1, "ok"), _job(2, "ok")]
    ex = LocalExecutor(workers=2, retries=0, task=fake_task)
    with ex:
        rows = run_jobs(jobs, tmp_path, cache_dir=tmp_path / "cache", show_progress=False, executor=ex)
    assert [r["job_id"] for r in rows] == [j.job_id for j in jobs]
    stored = {p.stem: json.loads(p.read_text()) for p in (tmp_path / "jobs").glob("*.json")}
    assert set(stored) == {j.job_id for j in jobs}
    assert stored[jobs[0].job_id]["error"]["type"] == WORKER_LOST
    assert not list((tmp_path / "jobs").glob(".*"))  # no temporaries left
    # a rerun: finished rows are skipped, the worker-lost one is tried again
    assert [needs_run(result_path(tmp_path, j)) for j in jobs] == [True, False, False]
    mtimes = {j.job_id: result_path(tmp_path, j).stat().st_mtime_ns for j in jobs[1:]}
    fixed = [Job(jobs[0].plan, {"tag": "ok"}, jobs[0].job_id)] + jobs[1:]  # the "cause" is gone now
    with LocalExecutor(workers=1, task=fake_task) as ex:
        run_jobs(fixed, tmp_path, cache_dir=tmp_path / "cache", show_progress=False, executor=ex)
    assert json.loads(result_path(tmp_path, jobs[0]).read_text())["status"] == "ok"
    assert {j.job_id: result_path(tmp_path, j).stat().st_mtime_ns for j in jobs[1:]} == mtimes


def test_a_job_that_raised_is_kept_on_rerun(tmp_path):
    job = _job(0, "x")
    path = result_path(tmp_path, job)
    path.parent.mkdir(parents=True)
    path.write_text(json.dumps(failure_row(job, "ValueError", "bad", "Traceback ...")))
    assert not needs_run(path) and needs_run(path, force=True)


@pytest.mark.parametrize("content", ["null", "[]", "3", "{not json"])
def test_a_stored_row_that_is_not_an_object_is_rerun(tmp_path, content):
    path = result_path(tmp_path, _job(0, "n"))
    path.parent.mkdir(parents=True)
    path.write_text(content)
    assert needs_run(path)


def test_duplicate_job_ids_run_once(tmp_path):
    calls = []

    def counting(job, cache_dir, attempt=1, threads=None, **kw):
        calls.append(job.job_id)
        return fake_task(job, cache_dir, attempt, threads)

    job = _job(0, "ok")
    rows = run_jobs([job, job], tmp_path, show_progress=False, executor=LocalExecutor(task=counting))
    assert calls == [job.job_id] and len(rows) == 2


def test_dask_executor_records_task_errors_and_results(tmp_path):
    from distributed import LocalCluster

    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cluster:
        ex = DaskExecutor(scheduler=cluster.scheduler_address, retries=1, poll_seconds=0.2, task=fake_task)
        jobs = [_job(0, "ok"), _job(1, "raise")]
        events = _events(ex, jobs, tmp_path)
    done = {e.job.job_id: e.row for e in events if e.kind == "done"}
    assert done[jobs[0].job_id]["status"] == "ok"
    bad = done[jobs[1].job_id]
    assert bad["status"] == "failed" and bad["error"]["type"] == "RuntimeError"
    assert "boom outside the job" in bad["error"]["traceback"] and "fake_task" in bad["error"]["traceback"]
    assert sum(e.kind == "retry" for e in events) == 0  # errors of the job are not retried


def _prepare(args):
    cache, barrier_file = args
    while not Path(barrier_file).exists():  # start both at the same moment
        time.sleep(0.01)
    prepare_dataset("scannet_like_tiny", "tiny", Path(cache))
    return sorted(p.name for p in Path(cache).iterdir() if not p.name.startswith("."))


@pytest.mark.slow
def test_two_workers_synthesising_the_same_dataset(tmp_path):
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    cache, go = tmp_path / "cache", tmp_path / "go"
    with ProcessPoolExecutor(2, mp_context=multiprocessing.get_context("spawn")) as pool:
        futs = [pool.submit(_prepare, (str(cache), str(go))) for _ in range(2)]
        go.touch()
        listings = [f.result(timeout=300) for f in futs]
    assert listings[0] == listings[1] and len(listings[0]) == 1  # one dataset folder, both saw it


def test_prepare_dataset_loser_of_an_unlocked_race_uses_the_winner(tmp_path, monkeypatch):
    import bench.data.datasets as datasets

    real = datasets.ensure_dataset
    calls = []

    def racy(*a, **k):
        calls.append(1)
        if len(calls) == 1:
            real(*a, **k)  # "the other worker" finishes first ...
            raise FileExistsError("target appeared")  # ... and we lose at the rename
        return real(*a, **k)

    monkeypatch.setattr(datasets, "ensure_dataset", racy)
    prepare_dataset("scannet_like_tiny", "tiny", tmp_path)
    assert len(calls) == 2 and len([p for p in tmp_path.iterdir() if not p.name.startswith(".")]) == 1


def test_make_executor_and_cli_flags(tmp_path, capsys):
    assert isinstance(make_executor("local", workers=2), LocalExecutor)
    assert isinstance(make_executor("dask", scheduler="tcp://127.0.0.1:1"), DaskExecutor)
    with pytest.raises(ValueError):
        make_executor("spark")
    base = ["run", "--table", "ablation", "--scale", "tiny", "--out", str(tmp_path), "--quiet"]
    assert main(base + ["--scheduler", "tcp://127.0.0.1:1"]) == 2
    assert "--scheduler" in capsys.readouterr().err
    assert main(base + ["--workers", "0"]) == 2
    assert main(base + ["--retries", "-1"]) == 2
    assert not (tmp_path / "tiny" / "jobs").exists()


@pytest.mark.skipif(sys.platform != "linux", reason="uses os.sched_getaffinity")
def test_pool_workers_get_their_share_of_threads(tmp_path):
    ex = LocalExecutor(workers=2)
    assert ex.threads == max(1, len(os.sched_getaffinity(0)) // 2)


@pytest.mark.slow
def test_sigterm_stops_the_workers(tmp_path):
    """A killed `bench run` (SIGTERM: `kill`, a CI timeout) exits 130 and leaves no worker training on."""
    import signal
    import subprocess
    import sys
    import time

    proc = subprocess.Popen([sys.executable, "-m", "bench.cli", "run", "--table", "dense", "--scale", "tiny", "--workers", "2",
                             "--out", str(tmp_path), "--quiet", "--force"], start_new_session=True,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 60
    while time.time() < deadline and len(_session_pids(proc.pid)) < 4:  # main, fork server, 2 workers
        time.sleep(0.5)
    assert len(_session_pids(proc.pid)) >= 4, "the worker pool did not start"
    time.sleep(2)  # the workers are inside their jobs now
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(timeout=30) == 130, proc.stderr.read()
    deadline = time.time() + 10
    while time.time() < deadline and _session_pids(proc.pid):
        time.sleep(0.2)
    assert not _session_pids(proc.pid)
    assert "interrupted" in proc.stderr.read()


def _session_pids(sid: int) -> list[int]:
    """Live processes of session ``sid`` (Linux /proc)."""
    import os

    pids = []
    for d in os.listdir("/proc"):
        if d.isdigit():
            try:
                fields = open(f"/proc/{d}/stat").read().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[3]) == sid and fields[0] != "Z":  # field 6 of stat: session id; skip zombies
                pids.append(int(d))
    return pids


_ORPHAN_SCRIPT = """
import multiprocessing.forkserver as fs, time
from bench.executors.local import LocalExecutor
pool = LocalExecutor(workers=2)._new_pool()
futures = [pool.submit(time.sleep, 120) for _ in range(2)]
time.sleep(0.5)
print(fs._forkserver._forkserver_pid, *pool._processes, flush=True)
time.sleep(120)
"""


def test_kill_9_of_the_main_process_takes_the_pool_with_it(tmp_path):
    """kill -9 of the process that started the pool (not its group): the fork server and both workers,
    busy with a 120 s task, are gone within seconds (bench.executors.lifeline)."""
    import subprocess

    import psutil

    proc = subprocess.Popen([sys.executable, "-c", _ORPHAN_SCRIPT], stdout=subprocess.PIPE, text=True,
                            cwd=Path(__file__).resolve().parents[2], start_new_session=True)
    try:
        pids = [int(p) for p in proc.stdout.readline().split()]
        assert len(pids) == 3, pids
        assert all(psutil.pid_exists(p) for p in pids)
        proc.kill()
        proc.wait(timeout=10)
        deadline = time.time() + 15
        alive = pids
        while alive and time.time() < deadline:
            time.sleep(0.2)
            alive = [p for p in alive if psutil.pid_exists(p) and psutil.Process(p).status() != psutil.STATUS_ZOMBIE]
        assert not alive, f"still running after kill -9 of their parent: {alive}"
    finally:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass


def test_a_damaged_cached_dataset_is_synthesised_again(tmp_path, capsys):
    """A file of a cached dataset damaged after it was written (here: cameras.npz truncated) would fail every
    job that uses it; the loader moves the copy aside and synthesises it again, once."""
    from bench.data.datasets import ensure_dataset, load_dataset

    folder = ensure_dataset("scannet_like_tiny", "tiny", tmp_path)
    good = load_dataset("scannet_like_tiny", "tiny", tmp_path)
    data = (folder / "cameras.npz").read_bytes()
    (folder / "cameras.npz").write_bytes(data[: len(data) // 3])
    again = load_dataset("scannet_like_tiny", "tiny", tmp_path)
    assert "damaged" in capsys.readouterr().err
    assert (again.images == good.images).all() and (folder / "cameras.npz").read_bytes() == data
    assert not [p for p in tmp_path.iterdir() if ".corrupt-" in p.name]
