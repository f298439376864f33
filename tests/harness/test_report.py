"""Aggregation, rendering and the claims check (bench/aggregate.py, bench/claims.py, bench/table_markdown.py,
bench/report.py) on synthetic result JSONs."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest
import yaml
from label_match import build_table_by_label

from bench.data.errors import BenchInputError
from bench.report import render_report, write_table_outputs
from bench.results_io import collect_results
from bench.table_markdown import to_markdown
from bench.table_spec import TableSpec, load_table_spec

SPEC: dict[str, Any] = {
    "name": "abl",
    "title": "Ablation test table",
    "paper_table": "Table 4",
    "datasets": [{
        "dataset": "scannet", "protocol": "scannet", "scenes": {"small": ["s0", "s1"]},
        "columns": [
            {"key": "acc", "label": "Acc", "direction": "lower", "unit": "m"},
            {"key": "fscore", "label": "F-score", "direction": "higher"},
        ],
    }],
    "seeds": {"small": [0, 1, 2]},
    "rows": [
        {"label": "Base", "method": "mi", "overrides": {"u": False}, "paper": {"scannet": {"acc": 0.039, "fscore": 0.749}}},
        {"label": "Full", "method": "mi", "overrides": {"u": True}, "paper": {"scannet": {"acc": 0.035, "fscore": 0.834}}},
        {"label": "Future", "method": "not_yet"},
        {"label": "Later", "method": "mi"},
    ],
    "paper_only_rows": [{"label": "MonoSDF", "paper": {"scannet": {"acc": 0.035, "fscore": 0.733}}}],
    "claims": [
        {"id": "rises", "text": "F rises", "kind": "monotone", "group": "scannet", "metric": "fscore",
         "rows": ["Base", "Full"], "direction": "increasing"},
        {"id": "falls", "text": "F falls", "kind": "monotone", "group": "scannet", "metric": "fscore",
         "rows": ["Base", "Full"], "direction": "decreasing"},
        {"id": "acc", "text": "Full more accurate", "kind": "better", "group": "scannet", "metric": "acc",
         "row_a": "Full", "row_b": "Base"},
        {"id": "later", "text": "Later beats Base", "kind": "better", "group": "scannet", "metric": "fscore",
         "row_a": "Later", "row_b": "Base"},
    ],
}
FSCORE = {"Base": 0.70, "Full": 0.80}


def job(row: str, scene: str, seed: int, status: str = "ok", **metrics: float) -> dict[str, Any]:
    f = FSCORE[row] + 0.01 * seed + (0.002 if scene == "s1" else 0.0)
    return {
        "job_id": f"{row}-{scene}-{seed}", "schema": 1, "table": "abl", "row": row, "method": "mi",
        "config": {}, "scene": scene, "dataset": "scannet", "seed": seed, "scale": "small", "status": status,
        "error": None if status == "ok" else {"type": "RuntimeError", "message": "loss is NaN", "traceback": "tb"},
        "metrics": {} if status != "ok" else {"fscore": f, "acc": 0.04, **metrics},
        "timings": {"data": 1.0, "train": 10.0 + seed, "total": 12.0 + seed} if status == "ok" else {"data": 1.0},
        "iterations": 100,
        "curve": [{"fraction": 0.5, "iterations": 50, "seconds": 6.0, "metrics": {"fscore": f / 2}}],
        "versions": {"bench": "0.1.0"}, "worker": "h:1", "created": f"2026-11-22T00:00:0{seed}",
    }


def write_jobs(results: Path, jobs: list[dict[str, Any]]) -> None:
    (results / "jobs").mkdir(parents=True, exist_ok=True)
    for j in jobs:
        (results / "jobs" / f"{j['job_id']}.json").write_text(json.dumps(j))


@pytest.fixture
def spec(tmp_path: Path) -> TableSpec:
    p = tmp_path / "abl.yaml"
    p.write_text(yaml.safe_dump(SPEC, sort_keys=False))
    return load_table_spec(p)


@pytest.fixture
def results(tmp_path: Path) -> Path:
    jobs = [job(r, s, seed) for r in ("Base", "Full") for s in ("s0", "s1") for seed in (0, 1, 2)]
    jobs = [j for j in jobs if not (j["row"] == "Base" and j["scene"] == "s1" and j["seed"] == 2)]
    jobs.append(job("Base", "s1", 2, status="failed"))
    write_jobs(tmp_path / "res", jobs)
    return tmp_path / "res"


def test_collect_results(results: Path) -> None:
    df = collect_results(results)
    assert len(df) == 12 and set(df["status"]) == {"ok", "failed"}
    assert collect_results(results / "nowhere").empty


def test_corrupt_json_names_the_file(tmp_path: Path) -> None:
    (tmp_path / "jobs").mkdir()
    bad = tmp_path / "jobs" / "x.json"
    bad.write_text("{not json")
    with pytest.raises(BenchInputError, match="corrupt result JSON") as e:
        collect_results(tmp_path)
    assert e.value.where == str(bad)
    bad.write_text(json.dumps({"job_id": "x"}))
    with pytest.raises(BenchInputError, match=r"missing key\(s\)"):
        collect_results(tmp_path)


def test_mean_std_and_marks(spec: TableSpec, results: Path) -> None:
    rep = build_table_by_label(spec, collect_results(results), "small", available_methods={"mi"})
    full = rep.cells[("Full", "scannet", "fscore")]
    per_seed = [0.801, 0.811, 0.821]  # mean over the two scenes per seed
    assert full.mean == pytest.approx(np.mean(per_seed))
    assert full.std == pytest.approx(np.std(per_seed, ddof=1))
    assert (full.n, full.n_expected, full.n_failed, full.status) == (6, 6, 0, "complete")
    base = rep.cells[("Base", "scannet", "fscore")]
    assert (base.n, base.n_failed, base.status) == (5, 1, "partial")
    assert rep.cells[("Future", "scannet", "fscore")].status == "not_implemented"
    assert rep.cells[("Later", "scannet", "fscore")].status == "pending"
    md = to_markdown(rep)
    assert "(5/6, 1 failed)" in md
    assert "pending (method not implemented yet)" in md
    assert "| **Later**" in md and "pending" in md
    assert "*paper: MonoSDF*" in md and "↳ *paper: Full*" in md and "0.834" in md
    assert "Stage timings" in md and "loss is NaN" in md


def test_superseded_results_use_the_latest(spec: TableSpec, results: Path) -> None:
    newer = job("Base", "s1", 2)
    newer["job_id"] = "rerun"
    newer["created"] = "2026-11-23T00:00:00"
    write_jobs(results, [newer])
    rep = build_table_by_label(spec, collect_results(results), "small")
    assert rep.cells[("Base", "scannet", "fscore")].status == "complete"
    assert rep.n_superseded == 1


def claim(rep: Any, cid: str) -> Any:
    return next(c for c in rep.claims if c.claim.id == cid)


def test_claims(spec: TableSpec, results: Path) -> None:
    rep = build_table_by_label(spec, collect_results(results), "small", available_methods={"mi"})
    assert claim(rep, "rises").verdict == "HELD"
    assert claim(rep, "rises").partial  # Base has a failed job
    assert "exceeds the combined spread" in claim(rep, "rises").details[0]
    assert "3 seeds" in claim(rep, "rises").details[0]
    assert claim(rep, "rises").paper_verdict == "HELD"
    assert claim(rep, "falls").verdict == "NOT HELD"
    assert claim(rep, "falls").paper_verdict == "NOT HELD"
    # equal acc: a strict claim does not hold on a tie, but a tie is inside any seed spread: undecided
    assert claim(rep, "acc").verdict == "UNDECIDED (within the seed spread: Full acc vs Base acc [scannet]; as measured: NOT HELD)"
    assert claim(rep, "later").verdict.startswith("UNDECIDED (missing rows")
    md = to_markdown(rep)
    assert "**HELD**" in md and "**NOT HELD**" in md and "**UNDECIDED" in md


@pytest.mark.parametrize("margin,verdict", [(0.05, "HELD"), (0.15, "NOT HELD")])
def test_better_claim_with_a_margin(tmp_path: Path, results: Path, margin: float, verdict: str) -> None:
    """Full (F ~0.81) beats Base (~0.71) by ~0.10: held with a 0.05 margin, not with 0.15."""
    obj = json.loads(json.dumps(SPEC))
    obj["claims"] = [{"id": "m", "text": "Full beats Base by a margin", "kind": "better", "group": "scannet",
                      "metric": "fscore", "row_a": "Full", "row_b": "Base", "margin": margin}]
    p = tmp_path / "abl.yaml"
    p.write_text(yaml.safe_dump(obj))
    rep = build_table_by_label(load_table_spec(p), collect_results(results), "small", available_methods={"mi"})
    assert rep.claims[0].verdict == verdict
    assert "by more than" in rep.claims[0].details[0] and rep.claims[0].paper_verdict == "n/a"
    obj["claims"][0]["margin"] = -1
    p.write_text(yaml.safe_dump(obj))
    with pytest.raises(BenchInputError, match="margin"):
        load_table_spec(p)


def _thin_vs_plane_report(tmp_path: Path, thin: tuple[float, float, float]) -> Any:
    """A table with one "greater" claim, Full unc_thin > unc_plane; unc_plane = 0.1 in every run, unc_thin per seed
    as given (3 seeds x 2 scenes)."""
    obj = json.loads(json.dumps(SPEC))
    obj["datasets"][0]["extra_metrics"] = ["unc_thin", "unc_plane"]
    obj["claims"] = [{"id": "g", "text": "thin > plane", "kind": "greater", "group": "scannet", "row": "Full",
                      "metric_a": "unc_thin", "metric_b": "unc_plane"}]
    p = tmp_path / "abl.yaml"
    p.write_text(yaml.safe_dump(obj))
    write_jobs(tmp_path / "r", [job("Full", s, seed, unc_thin=thin[seed], unc_plane=0.1) for s in ("s0", "s1") for seed in (0, 1, 2)])
    return build_table_by_label(load_table_spec(p), collect_results(tmp_path / "r"), "small")


def test_greater_claim_on_extra_metrics(tmp_path: Path) -> None:
    rep = _thin_vs_plane_report(tmp_path, (0.6, 0.6, 0.6))
    assert rep.claims[0].verdict == "HELD" and not rep.claims[0].partial


@pytest.mark.parametrize("thin,verdict", [
    ((0.6, 0.61, 0.62), "HELD"),  # beyond the spread
    ((0.12, 0.2, 0.0), "UNDECIDED (within the seed spread: Full unc_thin vs Full unc_plane [scannet]; as measured: HELD)"),
    ((0.08, 0.1, 0.0), "UNDECIDED (within the seed spread: Full unc_thin vs Full unc_plane [scannet]; as measured: NOT HELD)"),
    ((0.0, 0.01, 0.02), "NOT HELD"),  # against the claim beyond the spread
])
def test_a_claim_inside_the_seed_spread_is_undecided(tmp_path: Path, thin: tuple[float, float, float], verdict: str) -> None:
    assert _thin_vs_plane_report(tmp_path, thin).claims[0].verdict == verdict


def test_outputs_written_atomically(spec: TableSpec, results: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    rep = build_table_by_label(spec, collect_results(results), "small", available_methods={"mi"})
    paths = write_table_outputs(rep, out)
    assert sorted(p.name for p in out.iterdir()) == sorted(
        ["abl.csv", "abl.md", "abl_time.csv", "abl_curve.csv", "abl_accuracy_vs_time.png"])  # no temp files left
    assert paths["png"].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    tidy = pd.read_csv(paths["csv"])
    assert list(tidy.columns[:6]) == ["table", "row", "group", "dataset", "metric", "source"]
    ours = tidy[(tidy["row"] == "Full") & (tidy["metric"] == "fscore") & (tidy["source"] == "ours")].iloc[0]
    assert ours["mean"] == pytest.approx(rep.cells[("Full", "scannet", "fscore")].mean)
    assert ours["n"] == 6 and ours["n_failed"] == 0
    paper = tidy[(tidy["row"] == "MonoSDF") & (tidy["source"] == "paper") & (tidy["metric"] == "fscore")]
    assert paper["mean"].tolist() == [0.733]
    base = tidy[(tidy["row"] == "Base") & (tidy["metric"] == "fscore") & (tidy["source"] == "ours")].iloc[0]
    assert (base["n"], base["n_failed"], base["status"]) == (5, 1, "partial")
    time = pd.read_csv(paths["time_csv"])
    total = time[(time["row"] == "Full") & (time["quantity"] == "total")]["mean"].iloc[0]
    assert total == pytest.approx(13.0)
    assert {"data", "train", "total", "iterations"} <= set(time["quantity"])
    assert "| **Full**" in paths["md"].read_text()
    curve = pd.read_csv(paths["curve_csv"])
    full = curve[(curve["row"] == "Full") & (curve["metric"] == "fscore")]
    assert full[["fraction", "iterations", "seconds", "n"]].values.tolist() == [[0.5, 50, 6.0, 6]]
    full_jobs = rep.jobs[(rep.jobs["row"] == "Full") & (rep.jobs["status"] == "ok")]
    assert full["mean"].iloc[0] == pytest.approx(full_jobs["metrics"].map(lambda m: m["fscore"] / 2).mean())
    assert curve[(curve["row"] == "Base") & (curve["metric"] == "fscore")]["n"].tolist() == [5]  # the failed job has no curve


def test_render_report_and_empty_results(spec: TableSpec, tmp_path: Path) -> None:
    out = tmp_path / "out"
    path = render_report([spec], collect_results(tmp_path / "empty"), "small", out, plans={spec.name: {}})
    text = path.read_text()
    assert "# MonoInstance benchmark report" in text and "Ablation test table" in text
    assert "0 ok, 0 failed, 24 pending of 24 expected jobs" in text
    assert (out / "abl_accuracy_vs_time.png").exists()
    assert not [p for p in out.iterdir() if p.name.startswith(".")]
    with pytest.raises(BenchInputError, match="no scale 'tiny'"):
        render_report([spec], collect_results(tmp_path / "empty"), "tiny", out, plans={spec.name: {}})


def test_groups_sharing_a_dataset_split_by_overrides(tmp_path: Path) -> None:
    obj = json.loads(json.dumps(SPEC))
    g = obj["datasets"][0]
    obj["datasets"] = [{**g, "id": "p1", "overrides": {"prior_profile": "a"}},
                       {**g, "id": "p2", "overrides": {"prior_profile": "b"}}]
    obj["rows"] = [{"label": "Full", "method": "mi"}]
    obj["paper_only_rows"], obj["claims"] = [], []
    p = tmp_path / "abl.yaml"
    p.write_text(yaml.safe_dump(obj))
    spec = load_table_spec(p)
    jobs = []
    for prof, bump in (("a", 0.0), ("b", 0.1)):
        for s in ("s0", "s1"):
            for seed in (0, 1, 2):
                j = job("Full", s, seed)
                j["job_id"] += prof
                j["config"] = {"prior_profile": prof}
                j["metrics"]["fscore"] += bump
                jobs.append(j)
    write_jobs(tmp_path / "r", jobs)
    rep = build_table_by_label(spec, collect_results(tmp_path / "r"), "small")
    a, b = rep.cells[("Full", "p1", "fscore")], rep.cells[("Full", "p2", "fscore")]
    assert a.n == b.n == 6 and b.mean - a.mean == pytest.approx(0.1)
    assert math.isfinite(a.std)


def test_shipped_specs_render_without_results(tmp_path: Path) -> None:
    configs = Path(__file__).resolve().parents[2] / "configs" / "tables"
    specs = [load_table_spec(p) for p in sorted(configs.glob("*.yaml"))]
    path = render_report(specs, collect_results(tmp_path), "tiny", tmp_path / "out", available_methods={"oracle_tsdf"},
                         plans={s.name: {} for s in specs})
    text = path.read_text()
    assert "pending (method not implemented yet)" in text and "UNDECIDED" in text


def test_paper_unit_is_shown_and_kept_in_csv(tmp_path: Path) -> None:
    dtu = load_table_spec(Path(__file__).resolve().parents[2] / "configs" / "tables" / "dtu.yaml")
    rep = build_table_by_label(dtu, collect_results(tmp_path), "tiny")
    md = to_markdown(rep)
    assert "CD ↓ [m; paper: mm]" in md and "| 1.18 " in md
    paper = rep.tidy[rep.tidy["source"] == "paper"]
    assert set(paper["unit"]) == {"mm"}
    assert set(rep.tidy[rep.tidy["source"] == "ours"]["unit"]) == {"m"}


def test_table_outputs_are_all_or_nothing_on_a_full_disk(tmp_path, monkeypatch):
    """The disk fills while a table's files are written: no target file is touched, no temporary stays."""
    import os

    import bench.data.atomic as atomic

    real_fdopen, calls = os.fdopen, []

    def full_after_two(fd, mode="r", *a, **k):
        fh = real_fdopen(fd, mode, *a, **k)
        calls.append(1)
        if len(calls) > 2:
            fh.close()
            raise OSError(28, "No space left on device")
        return fh

    monkeypatch.setattr(atomic.os, "fdopen", full_after_two)
    files = {tmp_path / f"t{i}.csv": b"x" * 10 for i in range(5)}
    (tmp_path / "t0.csv").write_bytes(b"old")
    with pytest.raises(OSError, match="No space"):
        atomic.atomic_write_many(files)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t0.csv"] and (tmp_path / "t0.csv").read_bytes() == b"old"
    monkeypatch.setattr(atomic.os, "fdopen", real_fdopen)
    atomic.atomic_write_many(files)
    assert all(p.read_bytes() == b"x" * 10 for p in files)


def test_atomic_writes_get_the_usual_file_mode(tmp_path: Path) -> None:
    """Files written through a temporary (mkstemp: 0600) end with the mode open() would give (0666 - umask)."""
    import os

    from bench.data.atomic import atomic_write_bytes, atomic_write_many

    umask = os.umask(0o022)
    try:
        atomic_write_bytes(tmp_path / "a.png", b"x")
        atomic_write_many({tmp_path / "b.md": b"y"})
    finally:
        os.umask(umask)
    assert (tmp_path / "a.png").stat().st_mode & 0o777 == 0o644
    assert (tmp_path / "b.md").stat().st_mode & 0o777 == 0o644
