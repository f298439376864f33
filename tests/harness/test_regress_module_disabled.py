"""`bench regress` catches a module switched off on purpose, end to end at the tiny
scale: a reference is stored from the real "+Mono Uncertainty" row, then the same row is rerun with
its uncertainty module disabled in the table config. The module's own output (the uncertainty-quality
metrics, tracked as extra metrics) disappears, so the regression run must exit 1 and say which cells
went missing."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
import yaml

import bench.cli as cli
from bench.pipeline import SHIPPED_TABLES

pytestmark = pytest.mark.slow  # end to end (pyproject's `slow` marker; skipped by the fast loop -m 'not slow')

ROW = "+Mono Uncertainty"


def _tables_dir(tmp_path: Path, name: str, disable: str | None) -> Path:
    spec = yaml.safe_load((SHIPPED_TABLES / "ablation.yaml").read_text())
    if disable is not None:
        row = next(r for r in spec["rows"] if r["label"] == ROW)
        row["overrides"] = {**row["overrides"], disable: False}
    d = tmp_path / name
    d.mkdir()
    (d / "ablation.yaml").write_text(yaml.safe_dump(spec, sort_keys=False))
    return d


def test_regress_fails_when_the_uncertainty_module_is_disabled(tmp_path):
    ref_dir, out = tmp_path / "reference", tmp_path / "out"
    args = ["regress", "--table", "ablation", "--scale", "tiny", "--rows", ROW, "--quiet",
            "--out", str(out), "--reference-dir", str(ref_dir)]

    intact = ["--tables-dir", str(_tables_dir(tmp_path, "intact", None))]
    assert cli.main(args + intact + ["--update-reference"]) == 0
    stored = json.loads((ref_dir / "tiny" / "ablation.json").read_text())["cells"][ROW]["scannet"]
    assert {"fscore", "unc_mean_thin", "unc_mean_planar"} <= set(stored)

    assert cli.main(args + intact) == 0, "an unchanged rerun must pass (deterministic at one seed)"

    assert cli.main(args + ["--tables-dir", str(_tables_dir(tmp_path, "broken", "uncertainty"))]) == 1
    report = json.loads((out / "tiny" / "regress_ablation.json").read_text())
    assert report["passed"] is False
    missing = {f["metric"] for f in report["findings"] if f["verdict"] == "missing"}
    assert {"unc_mean_thin", "unc_mean_planar"} <= missing
    shutil.rmtree(out)
