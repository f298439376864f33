"""Table spec parsing and validation (bench/table_spec.py), and job planning (bench/pipeline.py)."""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import pytest
import yaml

from bench.data.errors import BenchInputError
from bench.pipeline import plan_jobs
from bench.table_spec import list_tables, load_table_spec, parse_table_spec, resolve

CONFIGS = Path(__file__).resolve().parents[2] / "configs"
SHIPPED = ["ablation", "dense", "dtu", "llff", "priors"]


def minimal() -> dict[str, Any]:
    """A small valid spec used as the base of the error cases."""
    return {
        "name": "t",
        "title": "T",
        "paper_table": "Table 9",
        "datasets": [{
            "dataset": "scannet", "protocol": "scannet",
            "scenes": {"tiny": ["a"], "small": ["a", "b"]},
            "columns": [
                {"key": "acc", "label": "Acc", "direction": "lower", "unit": "m"},
                {"key": "fscore", "label": "F", "direction": "higher"},
            ],
            "extra_metrics": ["unc"],
        }],
        "seeds": {"tiny": [0], "small": [0, 1]},
        "rows": [
            {"label": "A", "method": "m", "paper": {"scannet": {"fscore": 0.5}}},
            {"label": "B", "method": "m", "overrides": {"x": 1}},
        ],
        "paper_only_rows": [{"label": "P", "paper": {"scannet": {"acc": 0.1, "fscore": None}}}],
        "claims": [
            {"id": "c", "text": "B beats A", "kind": "better", "group": "scannet", "row_a": "B", "row_b": "A",
             "metric": "fscore"},
            {"id": "m", "text": "rises", "kind": "monotone", "group": "scannet", "rows": ["A", "B"],
             "metric": "fscore", "direction": "increasing"},
            {"id": "g", "text": "g", "kind": "greater", "group": "scannet", "row": "A", "metric_a": "unc",
             "metric_b": "fscore"},
        ],
    }


def write(tmp_path: Path, obj: Any, name: str = "t") -> Path:
    p = tmp_path / f"{name}.yaml"
    p.write_text(yaml.safe_dump(obj, sort_keys=False))
    return p


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_specs_load(name: str) -> None:
    spec = load_table_spec(CONFIGS / "tables" / f"{name}.yaml")
    assert spec.name == name
    for scale in ("tiny", "small"):
        jobs = plan_jobs(spec, scale)
        assert len(jobs) == sum(len(resolve(spec, scale).scenes[g.id]) for g in spec.groups) * len(
            spec.seeds[scale]) * len(spec.rows)
    assert all(r.paper is None or r.paper for r in spec.rows)


def test_list_tables() -> None:
    assert list_tables(CONFIGS) == SHIPPED
    assert list_tables(CONFIGS / "tables") == SHIPPED


def test_paper_values_match_the_tex() -> None:
    dense = load_table_spec(CONFIGS / "tables" / "dense.yaml")
    assert dense.row("MonoInstance (Full)").paper["scannet"]["fscore"] == 0.834  # type: ignore[index]
    assert dense.row("MonoSDF").paper["replica"]["nc"] == 0.921  # type: ignore[index]
    h2o = next(r for r in dense.paper_only_rows if r.label == "H2O-SDF")
    assert h2o.paper["replica"]["fscore"] is None  # type: ignore[index]
    priors = load_table_spec(CONFIGS / "tables" / "priors.yaml")
    assert [g.effects["prior_profile"]["profile"] for g in priors.groups] == ["sim-omnidata", "sim-metric3d-v2", "sim-geowizard"]
    assert "SIMULATED" in priors.title
    llff = load_table_spec(CONFIGS / "tables" / "llff.yaml")
    assert llff.groups[0].column("lpips").paper_only  # type: ignore[union-attr]


def test_minimal_loads_and_resolves(tmp_path: Path) -> None:
    spec = load_table_spec(write(tmp_path, minimal()))
    r = resolve(spec, "small")
    assert r.scenes == {"scannet": ("a", "b")} and r.seeds == (0, 1) and r.n_expected("scannet") == 4
    assert spec.main_metric()[1].key == "fscore"
    assert plan_jobs(spec, "tiny")[0].overrides == {}
    with pytest.raises(BenchInputError, match="no scale 'huge'"):
        resolve(spec, "huge")


def test_group_overrides_merge_under_row_overrides(tmp_path: Path) -> None:
    obj = minimal()
    obj["datasets"][0]["overrides"] = {"x": 0, "prior_profile": "p"}
    jobs = plan_jobs(load_table_spec(write(tmp_path, obj)), "tiny")
    assert {j.row: j.overrides for j in jobs} == {"A": {"x": 0, "prior_profile": "p"}, "B": {"x": 1, "prior_profile": "p"}}


def _mutate(path: str, value: Any, delete: bool = False) -> dict[str, Any]:
    obj = copy.deepcopy(minimal())
    parts = path.split("/")
    cur: Any = obj
    for p in parts[:-1]:
        cur = cur[int(p)] if isinstance(cur, list) else cur[p]
    last: Any = int(parts[-1]) if isinstance(cur, list) else parts[-1]
    if delete:
        del cur[last]
    else:
        cur[last] = value
    return obj


@pytest.mark.parametrize("path,value,delete,match", [
    ("colour", "x", False, r"unknown config key 'colour' \(known: anchors, claims"),
    ("datasets/0/columns/0/direction", "down", False, r"config key 'datasets\[0\]\.columns\[0\]\.direction' must be one of 'lower', 'higher' \(got 'down'\)"),
    ("datasets/0/columns/0/colour", 1, False, r"unknown config key 'datasets\[0\]\.columns\[0\]\.colour' of Column"),
    ("datasets/0/dataset", "kitti", False, r"datasets\[0\]\.dataset: unknown value 'kitti'"),
    ("datasets/0/scenes/small", None, True, r"datasets\[0\]\.scenes: missing scale\(s\) \['small'\]"),
    ("seeds/small", [0, 0], False, r"seeds\.small: duplicate"),
    ("seeds/tiny", ["0"], False, r"seeds\.tiny: seeds must be integers"),
    ("rows/0/method", None, True, r"config key 'rows\[0\]\.method' has no value"),
    ("rows/0/paper", {"scannet": {"acc": "x"}}, False, r"config key 'rows\[0\]\.paper\.scannet\.acc' must be a number or null"),
    ("rows/0/paper", {"replica": {"acc": 1}}, False, r"rows\[0\]\.paper\.replica: unknown group"),
    ("rows/0/paper", {"scannet": {"psnr": 1}}, False, r"rows\[0\]\.paper\.scannet\.psnr: unknown column"),
    ("rows/1/label", "A", False, r"rows: duplicate row label"),
    ("claims/0/row_b", "Z", False, r"claims\[0\]: unknown row 'Z'"),
    ("claims/0/metric", "psnr", False, r"claims\[0\]\.metric: unknown metric 'psnr'"),
    ("claims/0/group", "replica", False, r"claims\[0\]\.group: unknown group"),
    ("claims/1/direction", "up", False, r"config key 'claims\[1\]\.direction' must be one of 'increasing', 'decreasing' \(got 'up'\)"),
    ("claims/1/margin", 0.1, False, r"unknown config key 'claims\[1\]\.margin'"),  # a keyword of another claim kind
    ("claims/1/kind", "roughly", False, r"claims\[1\]\.kind: unknown value 'roughly'"),
    ("claims/2/metric_b", "nope", False, r"claims\[2\]\.metric: unknown metric 'nope'"),
    ("claims/0/metric", "unc", False, r"claims\[0\]\.direction: 'unc' is not a column"),
    ("name", "other", False, r"name: 'other' differs from the file name"),
    ("datasets/0/columns/0/fmt", ".3q", False, r"columns\[0\]\.fmt: bad format"),
])
def test_validation_errors_name_file_and_key(tmp_path: Path, path: str, value: Any, delete: bool, match: str) -> None:
    p = write(tmp_path, _mutate(path, value, delete))
    with pytest.raises(BenchInputError, match=match) as e:
        load_table_spec(p)
    assert e.value.where == str(p)


def test_missing_scale_in_seeds(tmp_path: Path) -> None:
    obj = minimal()
    obj["datasets"][0]["scenes"]["large"] = ["c"]
    with pytest.raises(BenchInputError, match=r"seeds: missing scale\(s\) \['large'\]"):
        load_table_spec(write(tmp_path, obj))


def test_duplicate_group_ids_need_an_id(tmp_path: Path) -> None:
    obj = minimal()
    obj["datasets"].append(copy.deepcopy(obj["datasets"][0]))
    with pytest.raises(BenchInputError, match="duplicate group ids"):
        load_table_spec(write(tmp_path, obj))
    obj["datasets"][1]["id"] = "second"
    assert [g.id for g in load_table_spec(write(tmp_path, obj)).groups] == ["scannet", "second"]


def test_bad_yaml_and_missing_file(tmp_path: Path) -> None:
    p = tmp_path / "t.yaml"
    p.write_text("name: [unclosed\n")
    with pytest.raises(BenchInputError, match="not valid YAML"):
        load_table_spec(p)
    with pytest.raises(BenchInputError, match="cannot read"):
        load_table_spec(tmp_path / "missing.yaml")
    p.write_text("- a list\n")
    with pytest.raises(BenchInputError, match="expected a mapping"):
        load_table_spec(p)


def test_paper_only_claim_metric_rejected(tmp_path: Path) -> None:
    obj = minimal()
    obj["datasets"][0]["columns"].append({"key": "lpips", "label": "LPIPS", "direction": "lower", "paper_only": True})
    obj["claims"][0]["metric"] = "lpips"
    with pytest.raises(BenchInputError, match="paper_only"):
        load_table_spec(write(tmp_path, obj))


def test_parse_in_memory_names_where() -> None:
    with pytest.raises(BenchInputError, match=r"^here: config key 'title' has no value"):
        parse_table_spec({"name": "x"}, "here")


def test_planning_many_seeds_reads_each_config_and_scene_once(monkeypatch):
    """500 seeds of a table are 3000 jobs: their configs and scene hashes are resolved once per distinct
    (method, overrides) and scene, not once per job (re-parsing the YAML per job took minutes)."""
    import yaml

    import bench.runner as runner
    from bench.pipeline import load_tables, plan_table

    parsed, hashed = [], []
    real_load, real_hash = yaml.safe_load, runner.scene_hash
    monkeypatch.setattr(yaml, "safe_load", lambda text: parsed.append(1) or real_load(text))
    monkeypatch.setattr(runner, "scene_hash", lambda *a: hashed.append(a) or real_hash(*a))
    spec = load_tables(["ablation"])[0]
    planned = plan_table(spec, "tiny", seeds=list(range(500)), threads=1)
    assert len(planned.jobs) == 500 * len(spec.rows) and len({j.job_id for j in planned.jobs}) == len(planned.jobs)
    assert len(parsed) < 20 and len(hashed) == 1  # the table, recipe and method files, not 2 per job
