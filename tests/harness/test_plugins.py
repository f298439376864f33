"""A method from an installed package (entry point group ``monoinstance_bench.methods``): the example
plugin in ``examples/plugin_method`` is pip-installed into a temporary site folder, appears in ``bench
list`` and runs in a tiny table given by path."""

from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path

import pytest

import methods.registry as registry
from bench.cli import main

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture()
def installed_plugin(tmp_path, monkeypatch):
    """``pip install`` of the example package (a copy of it, offline, no build isolation) into a temporary
    site folder put on sys.path: what a user's ``pip install my-method`` does, without touching the venv."""
    import subprocess

    src = tmp_path / "plugin_src"
    shutil.copytree(REPO / "examples" / "plugin_method", src)
    site = tmp_path / "site"
    subprocess.run([sys.executable, "-m", "pip", "install", "--no-build-isolation", "--no-deps", "--no-index", "-q",
                    "--target", str(site), str(src)], check=True, timeout=300)
    monkeypatch.syspath_prepend(str(site))
    monkeypatch.setattr(registry, "_plugins_loaded", False)
    yield site
    registry._REGISTRY.pop("metric_prior_tsdf", None)
    registry._PLUGIN_CONFIGS.pop("metric_prior_tsdf", None)
    sys.modules.pop("bench_example_method", None)


@pytest.mark.slow
def test_plugin_method_is_listed_and_runs_in_a_table_given_by_path(installed_plugin, tmp_path, capsys):
    assert main(["list"]) == 0
    assert "metric_prior_tsdf" in capsys.readouterr().out
    table = tmp_path / "mine.yaml"
    table.write_text("""
name: mine
title: "My table: a metric-prior TSDF against the oracle"
datasets:
  - id: scannet
    label: ScanNet-like
    dataset: scannet
    protocol: scannet
    scenes: {tiny: [scannet_like_tiny]}
    columns:
      - {key: fscore, label: F-score, direction: higher, unit: "", fmt: ".3f"}
seeds: {tiny: [0]}
rows:
  - {label: "Oracle", method: oracle_tsdf, paper: null}
  - {label: "Metric prior TSDF (plugin)", method: metric_prior_tsdf, paper: null}
""")
    out = tmp_path / "runs"
    assert main(["run", "--table", str(table), "--scale", "tiny", "--out", str(out), "--quiet", "--no-artifacts"]) == 0
    md = (out / "tiny" / "mine.md").read_text()
    assert "Metric prior TSDF (plugin)" in md and "2 ok, 0 failed, 0 pending" in md
    rows = [json.loads(p.read_text()) for p in (out / "tiny" / "jobs").glob("*.json")]
    plugin = [r for r in rows if r["method"] == "metric_prior_tsdf"]
    assert plugin and plugin[0]["status"] == "ok" and 0.0 <= plugin[0]["metrics"]["fscore"] <= 1.0
    assert not (out / "tiny" / "artifacts").exists()  # --no-artifacts


@pytest.mark.slow
def test_a_broken_plugin_is_one_clear_error(installed_plugin, capsys):
    (next(installed_plugin.glob("bench_example_method-*.dist-info")) / "entry_points.txt").write_text(
        "[monoinstance_bench.methods]\nbroken = bench_example_method:NoSuchClass\n")
    assert main(["list"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "plugin 'broken'" in err[0] and "NoSuchClass" in err[0]


@pytest.mark.slow
def test_a_table_may_name_a_dataset_folder_as_a_scene(tmp_path, capsys):
    """A user's own folder (here: a synthesised scene copied out of the cache, loaded as real data) as a
    table's scene; the job id follows the folder's bytes."""
    import shutil as sh

    from bench.data.datasets import ensure_dataset, scene_hash

    mine = tmp_path / "my_scan"
    sh.copytree(ensure_dataset("scannet_like_tiny", "tiny"), mine)
    table = tmp_path / "own.yaml"
    table.write_text(f"""
name: own
title: "Oracle on my own folder"
datasets:
  - {{id: scannet, label: Mine, dataset: scannet, protocol: scannet, scenes: {{tiny: ["{mine}"]}},
     columns: [{{key: fscore, label: F-score, direction: higher, unit: "", fmt: ".3f"}}]}}
seeds: {{tiny: [0]}}
rows:
  - {{label: "Oracle", method: oracle_tsdf, paper: null}}
""")
    out = tmp_path / "runs"
    assert main(["run", "--table", str(table), "--scale", "tiny", "--out", str(out), "--quiet", "--no-artifacts"]) == 0
    rows = [json.loads(p.read_text()) for p in (out / "tiny" / "jobs").glob("*.json")]
    assert len(rows) == 1 and rows[0]["status"] == "ok" and rows[0]["metrics"]["fscore"] > 0.9
    before = scene_hash(str(mine))
    (mine / "000000_rgb.png").write_bytes((mine / "000001_rgb.png").read_bytes())
    assert scene_hash(str(mine)) != before
    (mine / "cameras.npz").unlink()  # a broken folder: bad input before any job, not a table of failed cells
    assert main(["run", "--table", str(table), "--scale", "tiny", "--out", str(tmp_path / "again"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "cameras.npz: file is missing" in err[0], err
    assert not (tmp_path / "again").exists()


def test_installing_the_example_leaves_no_untracked_build_folder():
    """``pip install examples/plugin_method`` builds in ``examples/plugin_method/build/``: git ignores it."""
    import subprocess

    if shutil.which("git") is None or not (REPO / ".git").exists():
        pytest.skip("not a git checkout")
    probe = "examples/plugin_method/build/lib/bench_example_method/__init__.py"
    assert subprocess.run(["git", "check-ignore", "-q", "--no-index", probe], cwd=REPO).returncode == 0
