"""End to end: CLI, job runner (hash, atomic JSON, skip finished, failed rows), oracle row."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from bench.cli import main
from bench.executors.local import LocalExecutor
from bench.jobs import Job, JobPlan
from bench.machine import cpu_description
from bench.pipeline import plan_jobs
from bench.runner import job_id_for, plan_index, resolve_jobs, run_jobs
from bench.table_spec import load_table_spec
from methods.registry import available_methods, method_config

REPO = Path(__file__).resolve().parents[2]
ORACLE = "Oracle: TSDF of GT depth (upper bound)"


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    """`bench run --table ablation --scale tiny` once for the module (oracle row only until methods land)."""
    out = tmp_path_factory.mktemp("runs")
    code = main(["run", "--table", "ablation", "--scale", "tiny", "--rows", ORACLE, "--out", str(out), "--quiet"])
    return code, out / "tiny"


@pytest.mark.slow
def test_run_ablation_tiny_writes_table_with_oracle_row(tiny_run, capsys):
    code, out = tiny_run
    assert code == 0
    md = (out / "ablation.md").read_text()
    assert "Oracle" in md and "paper" in md.lower()
    for name in ("ablation.csv", "ablation_time.csv", "ablation_accuracy_vs_time.png"):
        assert (out / name).stat().st_size > 0
    rows = [json.loads(p.read_text()) for p in (out / "jobs").glob("*.json")]
    oracle = [r for r in rows if r["method"] == "oracle_tsdf"]
    assert oracle and all(r["status"] == "ok" for r in oracle), [r.get("error") for r in oracle]
    m = oracle[0]["metrics"]
    assert m["fscore"] >= 0.95, m  # acceptance: the oracle is an upper bound
    assert m["acc"] < 0.02 and m["comp"] < 0.03
    assert set(oracle[0]["timings"]) >= {"data", "train", "eval", "total"}
    assert oracle[0]["cpu"] == cpu_description() and f"Measured on: {cpu_description()}" in md  # times depend on it
    assert [c["fraction"] for c in oracle[0]["curve"]] == [0.25, 0.5, 1.0]
    art = oracle[0]["artifacts"]  # the final mesh is kept beside the numbers
    assert art["files"] == ["mesh.ply"] and (out / art["dir"] / "mesh.ply").stat().st_size > 1000
    assert "![reconstructions](ablation_reconstructions.png)" in md  # ... and drawn in the report
    assert (out / "ablation_reconstructions.png").stat().st_size > 5000


@pytest.mark.slow
def test_rerun_skips_finished_jobs(tiny_run, capsys):
    _, out = tiny_run
    files = {p: p.stat().st_mtime_ns for p in (out / "jobs").glob("*.json")}
    capsys.readouterr()
    assert main(["run", "--table", "ablation", "--scale", "tiny", "--rows", ORACLE, "--out", str(out.parent), "--quiet"]) == 0
    assert {p: p.stat().st_mtime_ns for p in (out / "jobs").glob("*.json")} == files
    printed = capsys.readouterr().out
    assert f"1 finished job(s) reused from {out / 'jobs'}; nothing to run" in printed and "0/0" not in printed
    wrote = next(line for line in printed.splitlines() if line.startswith("wrote "))
    for name in ("ablation.csv", "ablation_time.csv", "ablation_curve.csv", "ablation.md", "ablation_accuracy_vs_time.png",
                 "ablation_reconstructions.png"):
        assert str(out / name) in wrote  # every output the run wrote, not the first three
    assert not [p for p in out.rglob("*.tmp")]


@pytest.mark.slow
def test_report_command_assembles_markdown(tiny_run):
    _, out = tiny_run
    assert main(["report", "--table", "ablation", "--scale", "tiny", "--out", str(out.parent)]) == 0
    assert "Table 4" in (out / "report.md").read_text()


def test_job_id_depends_on_config_seed_and_scene():
    spec = load_table_spec(REPO / "configs" / "tables" / "ablation.yaml")
    plan = [p for p in plan_jobs(spec, "tiny") if p.method == "oracle_tsdf"][0]
    cfg = method_config("oracle_tsdf", "tiny")
    a = job_id_for(plan, cfg)
    assert a == job_id_for(plan, dict(cfg))
    assert a != job_id_for(plan, {**cfg, "voxel_size": 0.05})
    from dataclasses import replace

    assert a != job_id_for(replace(plan, seed=plan.seed + 1), cfg)
    assert a != job_id_for(replace(plan, scene="scannet_like_0"), cfg)


def test_failed_job_is_recorded_not_dropped(tmp_path):
    plan = JobPlan("t", "oracle", "oracle_tsdf", {}, "scannet", "scannet", "scannet", "scannet_like_tiny", 0, "tiny")
    cfg = {**method_config("oracle_tsdf", "tiny"), "voxel_size": "not-a-number"}
    rows = run_jobs([Job(plan, cfg, "deadbeefdeadbeef")], tmp_path, show_progress=False)
    assert rows[0]["status"] == "failed"
    assert rows[0]["error"]["type"] == "BenchInputError" and "Traceback" in rows[0]["error"]["traceback"]
    assert "'voxel_size' must be a number" in rows[0]["error"]["message"]
    assert json.loads((tmp_path / "jobs" / "deadbeefdeadbeef.json").read_text())["status"] == "failed"


@pytest.mark.parametrize("bad", [0, 2])
def test_unevaluable_snapshot(tmp_path, monkeypatch, bad):
    """An early snapshot that cannot be evaluated (e.g. an empty mesh) is a curve point without metrics;
    the final one failing fails the job, with the evaluator's message."""
    import bench.execute as execute

    real, calls = execute.evaluate_snapshot, []

    def flaky(snap, *a, **k):
        calls.append(snap.fraction)
        if len(calls) - 1 == bad:
            raise ValueError("pred_mesh is empty")
        return real(snap, *a, **k)

    monkeypatch.setattr(execute, "evaluate_snapshot", flaky)
    plan = JobPlan("t", "oracle", "oracle_tsdf", {}, "scannet", "scannet", "scannet", "scannet_like_tiny", 0, "tiny")
    row = run_jobs([Job(plan, method_config("oracle_tsdf", "tiny"), f"job{bad}")], tmp_path, show_progress=False,
                   executor=LocalExecutor(workers=1))[0]
    if bad == 0:
        assert row["status"] == "ok" and row["curve"][0]["metrics"] == {} and "empty" in row["curve"][0]["error"]
        assert row["metrics"]["fscore"] > 0.9 and len(row["curve"]) == 3
    else:
        assert row["status"] == "failed" and "pred_mesh is empty" in row["error"]["message"]


def test_pending_methods_are_reported_not_run():
    spec = load_table_spec(REPO / "configs" / "tables" / "ablation.yaml")
    jobs, pending = resolve_jobs(plan_jobs(spec, "tiny"))
    assert all(j.plan.method in available_methods() for j in jobs)
    assert all(p.method not in available_methods() for p in pending)


def test_unknown_override_key_is_an_error():
    from bench.data.errors import BenchInputError

    with pytest.raises(BenchInputError, match="voxel_sise"):
        method_config("oracle_tsdf", "tiny", {"voxel_sise": 0.1})


def test_cli_bad_input_prints_one_line_and_exits_2(tmp_path, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: x\nkind: room\nformat: scannet\neffects: [{name: warp_drive}]\n")
    assert main(["scenes", "make", str(bad), "--out", str(tmp_path / "o"), "--scale", "tiny"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "warp_drive" in err[0] and "bad.yaml" in err[0]
    assert not (tmp_path / "o").exists()
    assert main(["run", "--table", "no_such_table", "--scale", "tiny", "--out", str(tmp_path)]) == 2
    assert "no_such_table" in capsys.readouterr().err


def test_cli_list(capsys):
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    assert "oracle_tsdf" in out and "ablation" in out and "scannet_like_0" in out


def test_cli_scenes_make_then_load(tmp_path, capsys):
    from bench.data.formats import load_scene

    assert main(["scenes", "make", "dtu_like_0", "--out", str(tmp_path / "dtu"), "--scale", "tiny"]) == 0
    scene = load_scene(tmp_path / "dtu")
    assert scene.source_format == "dtu" and len(scene.view_indices("train")) == 3
    # the output exists now: making it again without --overwrite is a clear error
    assert main(["scenes", "make", "dtu_like_0", "--out", str(tmp_path / "dtu"), "--scale", "tiny"]) == 2


def test_jobs_that_train_run_before_fusion_only_jobs():
    """The oracle's short fusion-only jobs go last (they fill the tail); otherwise plan order is kept."""
    from types import SimpleNamespace

    from bench.runner import training_first

    jobs = [SimpleNamespace(config={}, job_id="oracle"), SimpleNamespace(config={"iterations": 600}, job_id="sdf1"),
            SimpleNamespace(config={"voxel_size": 0.02}, job_id="oracle2"), SimpleNamespace(config={"iterations": 300}, job_id="gs")]
    assert [j.job_id for j in training_first(jobs)] == ["sdf1", "gs", "oracle", "oracle2"]


def test_scene_filter_typo_and_empty_selection_exit_2(tmp_path, capsys):
    assert main(["run", "--table", "ablation", "--scale", "tiny", "--scenes", "scanet_like_tiny", "--out", str(tmp_path), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "scanet_like_tiny" in err[0] and "scannet_like_tiny" in err[0]
    assert not (tmp_path / "tiny" / "jobs").exists()


def test_unwritable_out_fails_before_any_job(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    assert main(["run", "--table", "ablation", "--scale", "tiny", "--rows", ORACLE, "--out", str(blocker / "sub"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not writable" in err[0] and "file" in err[0]


def test_failed_job_makes_run_exit_1_and_plain_log_has_a_line_per_job(tmp_path, monkeypatch, capsys):
    """Not a terminal (pytest captures stdout): one plain line per job event; a failed job still writes the
    tables, and the exit status says it failed."""
    import bench.execute as execute

    def broken(*a, **k):
        raise ValueError("evaluation exploded")

    monkeypatch.setattr(execute, "evaluate_snapshot", broken)
    code = main(["run", "--table", "ablation", "--scale", "tiny", "--rows", ORACLE, "--out", str(tmp_path), "--workers", "1"])
    captured = capsys.readouterr()
    assert code == 1
    assert "started Oracle" in captured.out and "failed Oracle" in captured.out
    assert "Scale 'tiny' is a smoke test" in captured.out.split("started Oracle")[0]  # said before the run, not only in the table
    assert "jobs failed" in captured.err
    assert (tmp_path / "tiny" / "ablation.md").exists()


@pytest.mark.slow
def test_thread_count_is_in_the_job_id_and_the_newest_result_counts(tmp_path):
    """Results depend on the torch thread count (float sums in another order), so a row computed with
    1 thread is not reused by a run planning 2 (issue 'Hard to break', item 6); the table matches both by
    the base id and shows the newest, counting the other as superseded."""
    import time

    spec = load_table_spec(REPO / "configs" / "tables" / "ablation.yaml")
    plans = [p for p in plan_jobs(spec, "tiny") if p.row == ORACLE]
    one, _ = resolve_jobs(plans, threads=1)
    two, _ = resolve_jobs(plans, threads=2)
    assert one[0].job_id != two[0].job_id and one[0].base_id == two[0].base_id == resolve_jobs(plans)[0][0].job_id
    for jobs in (one, two):
        run_jobs(jobs, tmp_path, show_progress=False)
        time.sleep(1.1)  # "created" has 1 s resolution
    assert len(list((tmp_path / "jobs").glob("*.json"))) == 2  # the 2-thread plan did not reuse the 1-thread row
    from bench.report import build_table
    from bench.results_io import collect_results

    rep = build_table(spec, collect_results(tmp_path), "tiny", available_methods(), plans=plan_index(two))
    assert rep.n_superseded == 1 and len(rep.jobs) == 1 and rep.jobs.iloc[0]["job_id"] == two[0].job_id
