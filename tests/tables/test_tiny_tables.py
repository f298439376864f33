"""The paper's tables at the tiny scale, end to end through the CLI (what `bench run` does at small scale,
in CI-sized form): every implemented row runs without failure and the report has its claims section."""

from __future__ import annotations

import json

import pytest

from bench.cli import main


@pytest.mark.parametrize("table", ["ablation", "dense", "llff"])
def test_tiny_table_runs_end_to_end(table, tmp_path, capsys):
    assert main(["run", "--table", table, "--scale", "tiny", "--out", str(tmp_path), "--quiet"]) == 0
    out = tmp_path / "tiny"
    rows = [json.loads(p.read_text()) for p in (out / "jobs").glob("*.json")]
    assert rows and all(r["status"] == "ok" for r in rows), [(r["row"], r.get("error", {}).get("message")) for r in rows if r["status"] != "ok"]
    md = (out / f"{table}.md").read_text()
    assert "## Claims" in md and f"{len(rows)} ok, 0 failed, 0 pending" in md
    assert (out / f"{table}_accuracy_vs_time.png").stat().st_size > 0
    for r in rows:  # every row carries its cost in time, per stage
        assert r["timings"]["total"] > 0 and r["curve"], r["row"]
