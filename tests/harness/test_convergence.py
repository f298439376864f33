"""Convergence criteria (bench/convergence.py): per run, per row, and their effect on tables and claims."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import pandas as pd
import pytest
import yaml
from label_match import build_table_by_label

from bench.convergence import ConvergenceSpec, check_run, judge_row
from bench.results_io import collect_results
from bench.table_markdown import to_markdown
from bench.table_spec import load_table_spec

F = ConvergenceSpec()  # F-score: flat 0.03, drop 0.05, seed std 0.03


def test_run_checks_follow_the_issue_criteria() -> None:
    c = check_run([0.25, 0.5, 1.0], [0.50, 0.80, 0.82], F)
    assert c.flat and c.no_drop and c.half == 0.80 and c.final == 0.82
    assert not check_run([0.25, 0.5, 1.0], [0.4, 0.6, 0.8], F).flat  # still climbing
    late_drop = check_run([1.0, 0.25, 0.5, 0.75], [0.80, 0.7, 0.8, 0.7], F)  # any order
    assert late_drop.flat and not late_drop.no_drop and late_drop.max_drop == pytest.approx(0.1)
    early = check_run([0.125, 0.25, 0.5, 1.0], [0.9, 0.5, 0.8, 0.8], F)  # a drop up to 25 % is allowed
    assert early.flat and early.no_drop
    lost = check_run([0.25, 0.5, 1.0], [0.5, 0.5, math.nan], F)
    assert not lost.flat and not lost.no_drop


def test_an_error_metric_drops_when_it_rises() -> None:
    chamfer = ConvergenceSpec(metric="cd", flat=0.001, drop=0.002, higher_is_better=False)
    assert check_run([0.25, 0.5, 1.0], [0.010, 0.012, 0.0125], chamfer).no_drop  # rose by 0.002: not more than drop
    rising = check_run([0.25, 0.5, 1.0], [0.010, 0.015, 0.0152], chamfer)
    assert rising.flat and not rising.no_drop and rising.max_drop == pytest.approx(0.005)
    assert check_run([0.25, 0.5, 1.0], [0.02, 0.012, 0.010], chamfer).no_drop  # falling error: fine


def curve(*f: float) -> list[dict[str, Any]]:
    fr = [0.25, 0.5, 1.0]
    return [{"fraction": x, "iterations": int(x * 100), "metrics": {"fscore": v}} for x, v in zip(fr, f)]


TRAINED = {"iterations": 100}


def test_row_verdict_counts_runs_and_the_seed_spread() -> None:
    flat = [(s, curve(0.5, 0.80 + 0.01 * s, 0.80 + 0.01 * s), TRAINED) for s in range(3)]
    v = judge_row(flat, F)
    assert v.converged and v.n_runs == 3 and v.seed_std == pytest.approx(0.01) and v.label() == "yes"
    spread = [(s, curve(0.5, 0.5 + 0.2 * s, 0.5 + 0.2 * s), TRAINED) for s in range(3)]
    v = judge_row(spread, F)
    assert not v.converged and v.label() == "NO (seed std 0.200 > 0.03)"
    climbing = [(0, curve(0.3, 0.4, 0.8), TRAINED), (1, curve(0.3, 0.8, 0.8), TRAINED)]
    assert judge_row(climbing, F).label().startswith("NO (flat 1/2")
    one_seed = judge_row([(0, curve(0.5, 0.8, 0.8), TRAINED)], F)
    assert one_seed.converged and math.isnan(one_seed.seed_std) and "one seed" in one_seed.label()
    fusion = judge_row([(0, curve(0.3, 0.6, 0.9), {"voxel_size": 0.02})], F)  # no optimisation schedule
    assert not fusion.judged and not fusion.converged and fusion.label() == "-"
    zero = judge_row([(0, curve(0.0, 0.0, 0.0), TRAINED)], F)  # a lost reconstruction at F = 0 is a value, not NaN
    assert zero.converged


SPEC: dict[str, Any] = {
    "name": "conv", "title": "Convergence test table",
    "datasets": [{"dataset": "scannet", "protocol": "scannet", "scenes": {"small": ["s0"]},
                  "columns": [{"key": "fscore", "label": "F-score", "direction": "higher"}]}],
    "seeds": {"small": [0, 1, 2]},
    "rows": [{"label": "Oracle", "method": "fusion"}, {"label": "Base", "method": "sdf"}, {"label": "Full", "method": "sdf"}],
    "convergence": {"metric": "fscore"},
    "claims": [{"id": "full_beats_base", "text": "Full beats Base", "kind": "better", "group": "scannet",
                "metric": "fscore", "row_a": "Full", "row_b": "Base"},
               {"id": "oracle_beats_base", "text": "Oracle beats Base", "kind": "better", "group": "scannet",
                "metric": "fscore", "row_a": "Oracle", "row_b": "Base"}],
}


def write_table(tmp_path: Path, curves: dict[str, list[float]], spec: dict[str, Any] = SPEC, scale: str = "small",
                seeds: tuple[int, ...] = (0, 1, 2)) -> Any:
    (tmp_path / "res" / "jobs").mkdir(parents=True)
    spec = {**spec, "seeds": {scale: list(seeds)},
            "datasets": [{**spec["datasets"][0], "scenes": {scale: ["s0"]}}]}
    for row, shape in curves.items():
        for seed in seeds:
            f = [x + 0.001 * seed for x in shape]
            j = {"job_id": f"{row}-{seed}", "table": "conv", "row": row, "method": "x", "scene": "s0", "dataset": "scannet",
                 "seed": seed, "scale": scale, "status": "ok", "metrics": {"fscore": f[-1]}, "timings": {"total": 1.0},
                 "config": {} if row == "Oracle" else {"iterations": 100}, "curve": curve(*f), "created": "2026-12-02T00:00:00"}
            (tmp_path / "res" / "jobs" / f"{row}-{seed}.json").write_text(json.dumps(j))
    p = tmp_path / "conv.yaml"
    p.write_text(yaml.safe_dump(spec, sort_keys=False))
    return build_table_by_label(load_table_spec(p), collect_results(tmp_path / "res"), scale)


def test_a_claim_on_an_unconverged_row_is_undecided(tmp_path: Path) -> None:
    rep = write_table(tmp_path, {"Oracle": [0.5, 0.8, 0.99], "Base": [0.5, 0.6, 0.7], "Full": [0.6, 0.8, 0.81]})
    verdicts = {c.claim.id: c.verdict for c in rep.claims}
    assert verdicts["full_beats_base"] == "UNDECIDED (not converged: Base [scannet]; as measured: HELD)"
    assert verdicts["oracle_beats_base"].startswith("UNDECIDED (not converged: Base")
    assert not rep.convergence[("Oracle", "scannet")].judged  # fusion: its climbing curve counts views
    md = to_markdown(rep)
    assert "| converged" in md and "NO (flat 0/3)" in md and "A row that has not converged is not a result" in md
    tidy = rep.tidy[rep.tidy["source"] == "ours"].set_index("row")["converged"]
    assert [tidy["Base"], tidy["Full"]] == [False, True] and pd.isna(tidy["Oracle"])


def test_converged_rows_keep_the_verdict_and_no_spec_changes_nothing(tmp_path: Path) -> None:
    rep = write_table(tmp_path, {"Oracle": [0.5, 0.8, 0.99], "Base": [0.5, 0.7, 0.7], "Full": [0.6, 0.8, 0.81]})
    assert [c.verdict for c in rep.claims] == ["HELD", "HELD"]
    plain = {k: v for k, v in SPEC.items() if k != "convergence"}
    rep = write_table(tmp_path / "plain", {"Oracle": [0.5, 0.8, 0.99], "Base": [0.5, 0.6, 0.7], "Full": [0.6, 0.8, 0.81]}, plain)
    assert [c.verdict for c in rep.claims] == ["HELD", "HELD"] and rep.convergence == {}
    assert "converged" not in to_markdown(rep).split("## Claims")[0].split("\n\n")[1]


CLEAR = {"Oracle": [0.5, 0.8, 0.99], "Base": [0.5, 0.7, 0.7], "Full": [0.6, 0.8, 0.81]}  # converged, Full ahead by 0.11


def test_one_seed_leaves_every_claim_undecided_with_the_measured_verdict(tmp_path: Path) -> None:
    rep = write_table(tmp_path, CLEAR, seeds=(0,))
    assert [c.verdict for c in rep.claims] == [
        "UNDECIDED (spread unknown, one seed: Full fscore vs Base fscore [scannet]; as measured: HELD)",
        "UNDECIDED (spread unknown, one seed: Oracle fscore vs Base fscore [scannet]; as measured: HELD)"]


def test_the_tiny_scale_is_a_smoke_test_in_every_output(tmp_path: Path) -> None:
    """At ``tiny`` no row gets a convergence verdict and no claim a decision, even on curves that would pass at
    another scale, and the markdown says that the table is a smoke test."""
    rep = write_table(tmp_path, CLEAR, scale="tiny", seeds=(0, 1, 2))
    assert {v.label() for v in rep.convergence.values()} == {"n/a (smoke test)"}
    assert rep.tidy[rep.tidy["source"] == "ours"]["converged"].isna().all()
    assert [c.verdict for c in rep.claims] == ["UNDECIDED (smoke test at scale 'tiny': not a result; as measured: HELD)"] * 2
    md = to_markdown(rep)
    assert "**Smoke test.** Scale 'tiny' is a smoke test" in md.split("| Method")[0]
    assert "smoke test" not in to_markdown(write_table(tmp_path / "small", CLEAR)).lower()


def test_bad_convergence_block_names_the_key(tmp_path: Path) -> None:
    from bench.data.errors import BenchInputError

    p = tmp_path / "conv.yaml"
    p.write_text(yaml.safe_dump({**SPEC, "convergence": {"metric": "psnr"}}, sort_keys=False))
    with pytest.raises(BenchInputError, match="convergence.metric"):
        load_table_spec(p)
    p.write_text(yaml.safe_dump({**SPEC, "convergence": {"metric": "fscore", "flat": -1}}, sort_keys=False))
    with pytest.raises(BenchInputError, match="convergence.flat"):
        load_table_spec(p)
    p.write_text(yaml.safe_dump({**SPEC, "convergence": {"metric": "fscore", "plateau": 0.1}}, sort_keys=False))
    with pytest.raises(BenchInputError, match="unknown config key 'convergence.plateau'"):
        load_table_spec(p)
