"""Regression comparison (bench/regress.py) on constructed results: one-sided tolerance, improvements,
missing and failed rows, rows without a reference; plus the `bench regress` exit codes end to end."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
import yaml
from label_match import build_table_by_label

from bench.cli import main
from bench.data.errors import BenchInputError
from bench.regress import RegressResult, compare, make_reference, summarise, to_markdown
from bench.results_io import collect_results
from bench.table_spec import TableSpec, load_table_spec

SPEC: dict[str, Any] = {
    "name": "abl", "title": "Regression test table", "paper_table": "Table 4",
    "datasets": [{
        "dataset": "scannet", "protocol": "scannet", "scenes": {"small": ["s0", "s1"]},
        "columns": [
            {"key": "acc", "label": "Acc", "direction": "lower", "unit": "m"},
            {"key": "fscore", "label": "F-score", "direction": "higher"},
        ],
    }],
    "seeds": {"small": [0, 1, 2]},
    "rows": [
        {"label": "Oracle", "method": "mi"},
        {"label": "Full", "method": "mi"},
        {"label": "Future", "method": "not_yet"},
    ],
}


def job(row: str, scene: str, seed: int, fscore: float, acc: float = 0.04, status: str = "ok") -> dict[str, Any]:
    return {
        "job_id": f"{row}-{scene}-{seed}", "schema": 1, "table": "abl", "row": row, "method": "mi", "config": {},
        "scene": scene, "dataset": "scannet", "seed": seed, "scale": "small", "status": status,
        "error": None if status == "ok" else {"type": "RuntimeError", "message": "loss is NaN", "traceback": "tb"},
        "metrics": {"fscore": fscore + 0.002 * seed, "acc": acc} if status == "ok" else {},
        "timings": {"total": 1.0}, "iterations": 1, "curve": [], "versions": {}, "worker": "h:1",
        "created": f"2026-11-22T00:00:0{seed}",
    }


@pytest.fixture
def spec(tmp_path: Path) -> TableSpec:
    p = tmp_path / "abl.yaml"
    p.write_text(yaml.safe_dump(SPEC, sort_keys=False))
    return load_table_spec(p)


def summary(spec: TableSpec, tmp_path: Path, name: str, jobs: list[dict[str, Any]]):
    d = tmp_path / name / "jobs"
    d.mkdir(parents=True)
    for j in jobs:
        (d / f"{j['job_id']}.json").write_text(json.dumps(j))
    return build_table_by_label(spec, collect_results(d.parent), "small", ["mi"])


def table(fs: dict[str, float], acc: float = 0.04, skip: set[str] = frozenset(), fail: set[str] = frozenset()):
    return [job(row, scene, seed, f, acc, "failed" if (row, scene, seed) in fail else "ok")
            for row, f in fs.items() if row not in skip for scene in ("s0", "s1") for seed in (0, 1, 2)
            if (row, scene, seed) not in skip]


@pytest.fixture
def reference(spec, tmp_path):
    return make_reference(spec, summary(spec, tmp_path, "ref", table({"Oracle": 0.99, "Full": 0.80})))


def verdicts(findings, row=None):
    return {(f.row, f.metric): f.verdict for f in findings if row is None or f.row == row}


def run_compare(spec, tmp_path, reference, jobs):
    report = summary(spec, tmp_path, "new", jobs)
    return RegressResult("abl", "small", compare(reference, summarise(spec, report), ["Future"]))


def test_reference_holds_mean_spread_n_per_cell(reference):
    cell = reference["cells"]["Full"]["scannet"]["fscore"]
    assert cell["mean"] == pytest.approx(0.802) and cell["std"] == pytest.approx(0.002) and cell["n"] == 6
    assert cell["direction"] == "higher" and reference["tolerance"]["floors"]["acc"] == 0.002
    assert "Future" not in reference["cells"]  # pending method: no reference


def test_passes_within_tolerance(spec, tmp_path, reference):
    res = run_compare(spec, tmp_path, reference, table({"Oracle": 0.99, "Full": 0.795}, acc=0.041))
    assert res.passed, to_markdown(res)
    assert verdicts(res.findings, "Full") == {("Full", "acc"): "ok", ("Full", "fscore"): "ok"}


def test_fails_when_a_row_got_worse_beyond_tolerance(spec, tmp_path, reference):
    res = run_compare(spec, tmp_path, reference, table({"Oracle": 0.99, "Full": 0.75}))
    assert not res.passed
    assert verdicts(res.findings)[("Full", "fscore")] == "regressed"
    assert verdicts(res.findings)[("Oracle", "fscore")] == "ok"
    assert "| regressed | Full |" in to_markdown(res)


def test_lower_is_better_direction(spec, tmp_path, reference):
    worse = run_compare(spec, tmp_path, reference, table({"Oracle": 0.99, "Full": 0.80}, acc=0.05))
    assert verdicts(worse.findings)[("Full", "acc")] == "regressed"
    better = run_compare(spec, tmp_path / "b", reference, table({"Oracle": 0.99, "Full": 0.80}, acc=0.03))
    assert better.passed and verdicts(better.findings)[("Full", "acc")] == "improved"


def test_reports_improvements_and_passes(spec, tmp_path, reference):
    res = run_compare(spec, tmp_path, reference, table({"Oracle": 0.99, "Full": 0.86}))
    assert res.passed
    assert [(f.row, f.metric) for f in res.by_verdict("improved")] == [("Full", "fscore")]
    assert "improved" in to_markdown(res)


def test_tolerance_scales_with_the_reference_spread(spec, tmp_path):
    noisy = table({"Oracle": 0.99, "Full": 0.80})
    for j in noisy:  # seed spread 0.02 in F-score -> tolerance 3 x 0.02 = 0.06
        j["metrics"]["fscore"] += 0.018 * j["seed"]
    ref = make_reference(spec, summary(spec, tmp_path, "ref", noisy))
    tol = 3 * ref["cells"]["Full"]["scannet"]["fscore"]["std"]
    assert tol > 0.05
    res = run_compare(spec, tmp_path, ref, table({"Oracle": 0.99, "Full": 0.80 + 0.02 - 0.04}))
    assert verdicts(res.findings)[("Full", "fscore")] == "ok"  # 0.04 worse, within 3 spreads


def test_missing_row_fails(spec, tmp_path, reference):
    res = run_compare(spec, tmp_path, reference, table({"Oracle": 0.99, "Full": 0.80}, skip={"Full"}))
    assert not res.passed and verdicts(res.findings, "Full") == {("Full", "acc"): "missing", ("Full", "fscore"): "missing"}


def test_partly_missing_or_failed_jobs_fail(spec, tmp_path, reference):
    part = run_compare(spec, tmp_path, reference, table({"Oracle": 0.99, "Full": 0.80}, skip={("Full", "s1", 2)}))
    assert verdicts(part.findings)[("Full", "fscore")] == "missing" and not part.passed
    failed = run_compare(spec, tmp_path / "f", reference, table({"Oracle": 0.99, "Full": 0.80}, fail={("Full", "s0", 1)}))
    assert verdicts(failed.findings)[("Full", "fscore")] == "failed" and not failed.passed


def test_rows_without_reference_are_not_failures(spec, tmp_path, reference):
    ref = json.loads(json.dumps(reference))
    del ref["cells"]["Full"]  # e.g. a method that was pending when the reference was made
    res = run_compare(spec, tmp_path, ref, table({"Oracle": 0.99, "Full": 0.10}))
    assert res.passed
    assert verdicts(res.findings, "Full") == {("Full", "acc"): "no_reference", ("Full", "fscore"): "no_reference"}
    assert verdicts(res.findings, "Future") == {("Future", "*"): "pending"}


def test_reference_refused_when_jobs_failed(spec, tmp_path):
    report = summary(spec, tmp_path, "ref", table({"Oracle": 0.99, "Full": 0.80}, fail={("Full", "s0", 0)}))
    with pytest.raises(BenchInputError, match="refusing"):
        make_reference(spec, report)


@pytest.mark.slow
def test_regress_cli_exit_codes(tmp_path, capsys):
    """`bench regress` end to end at tiny scale: no reference -> skipped (0); --update-reference stores
    one; the same code passes (0); a reference tampered to look better makes it fail (1)."""
    refs, out = tmp_path / "reference", tmp_path / "out"
    oracle = "Oracle: TSDF of GT depth (upper bound)"
    base = ["regress", "--table", "ablation", "--scale", "tiny", "--rows", oracle, "--out", str(out), "--reference-dir", str(refs), "--quiet"]
    assert main(base) == 0 and "no reference yet" in capsys.readouterr().out
    assert main(base + ["--update-reference"]) == 0
    path = refs / "tiny" / "ablation.json"
    doc = json.loads(path.read_text())
    oracle = next(r for r in doc["cells"] if r.startswith("Oracle"))
    from methods.registry import available_methods

    spec = load_table_spec(Path(__file__).resolve().parents[2] / "configs" / "tables" / "ablation.yaml")
    assert set(doc["cells"]) == {oracle} and spec.row(oracle).method in available_methods()  # the selected rows only
    capsys.readouterr()
    assert main(base) == 0
    assert (out / "tiny" / "regress_ablation.md").read_text().startswith("# Regression: table `ablation`, scale `tiny`: PASSED")
    assert f"table ablation: passed; report {out / 'tiny' / 'regress_ablation.md'} (and .json)" in capsys.readouterr().out
    doc["cells"][oracle]["scannet"]["fscore"]["mean"] += 0.1  # the reference was 0.1 better
    path.write_text(json.dumps(doc))
    capsys.readouterr()
    assert main(base) == 1
    text = capsys.readouterr().out
    assert "regressed" in text and "REGRESSION in ablation" in text


@pytest.mark.slow
def test_reference_from_stored_results_without_a_fresh_run(tmp_path):
    """`--from-results DIR` stores / checks a reference from a finished `bench run` (no job reruns)."""
    oracle = "Oracle: TSDF of GT depth (upper bound)"
    runs, ref = tmp_path / "runs", tmp_path / "ref"
    assert main(["run", "--table", "ablation", "--scale", "tiny", "--rows", oracle, "--out", str(runs), "--quiet", "--workers", "1"]) == 0
    stamp = {p.name: p.stat().st_mtime_ns for p in (runs / "tiny" / "jobs").glob("*.json")}
    base = ["regress", "--table", "ablation", "--scale", "tiny", "--rows", oracle, "--from-results", str(runs),
            "--reference-dir", str(ref), "--out", str(tmp_path / "reg"), "--quiet"]
    assert main(base + ["--update-reference"]) == 0
    assert json.loads((ref / "tiny" / "ablation.json").read_text())["cells"][oracle]["scannet"]["fscore"]["mean"] > 0.9
    assert main(base) == 0
    assert {p.name: p.stat().st_mtime_ns for p in (runs / "tiny" / "jobs").glob("*.json")} == stamp  # nothing rerun
