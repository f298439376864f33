"""Nightly regression (run with ``pytest -m nightly``): ``bench regress`` at the tiny scale against the
stored reference ``results/reference/tiny/ablation.json``; fails on any regression, failed job or
missing row."""

from __future__ import annotations

import pytest

from bench.cli import main


@pytest.mark.nightly
def test_regress_ablation_tiny(tmp_path):
    assert main(["regress", "--table", "ablation", "--scale", "tiny", "--out", str(tmp_path), "--quiet"]) == 0
    assert "PASSED" in (tmp_path / "tiny" / "regress_ablation.md").read_text()
