"""`bench study convergence`: dense snapshots along the schedule, exact priors, a sweep, CSV / plot / summary."""

from __future__ import annotations

import pandas as pd
import pytest

from bench.cli import main
from bench.convergence import ConvergenceSpec
from bench.overrides import parse_sweep
from bench.study import convergence_checks, exact_priors_choice, load_study_scene, study_convergence_spec


def test_convergence_checks_follow_the_issue_criteria():
    flat = pd.DataFrame({"fraction": [0.25, 0.5, 0.75, 1.0], "fscore": [0.5, 0.80, 0.81, 0.82]})
    assert convergence_checks(flat) == {"flat": True, "no_drop": True, "half": 0.80, "max_drop": pytest.approx(0.0)}
    climbing = pd.DataFrame({"fraction": [0.25, 0.5, 0.75, 1.0], "fscore": [0.5, 0.6, 0.7, 0.8]})
    assert not convergence_checks(climbing)["flat"]
    swinging = pd.DataFrame({"fraction": [0.25, 0.5, 0.75, 1.0], "fscore": [0.7, 0.8, 0.7, 0.8]})
    c = convergence_checks(swinging)
    assert c["flat"] and not c["no_drop"] and c["max_drop"] == pytest.approx(0.1)


def test_a_study_judges_by_the_criteria_of_the_table_of_its_protocol():
    dtu = study_convergence_spec("dtu")  # Table 2: the Chamfer distance, lower is better
    assert dtu.metric == "cd" and not dtu.higher_is_better
    assert study_convergence_spec("scannet").metric == "fscore" == study_convergence_spec("replica").metric
    # an error metric: a rise is a worsening, a fall is not
    spec = ConvergenceSpec(metric="cd", flat=0.0006, drop=0.001, higher_is_better=False)
    falling = pd.DataFrame({"fraction": [0.25, 0.5, 0.75, 1.0], "cd": [0.020, 0.0105, 0.0102, 0.0100]})
    assert convergence_checks(falling, spec) == {"flat": True, "no_drop": True, "half": 0.0105, "max_drop": pytest.approx(0.0)}
    rising = pd.DataFrame({"fraction": [0.25, 0.5, 0.75, 1.0], "cd": [0.010, 0.010, 0.012, 0.011]})
    c = convergence_checks(rising, spec)
    assert not c["flat"] and not c["no_drop"] and c["max_drop"] == pytest.approx(0.002)


def test_exact_priors_replace_the_chosen_prior_only():
    import numpy as np

    shipped = load_study_scene("scannet_like_tiny", "tiny", "none")
    assert not np.array_equal(shipped.mono_depth, shipped.gt_depth)  # the shipped prior is not exact: the test can fail
    assert not np.array_equal(shipped.mono_normal, shipped.gt_normal)
    for which, depth_exact, normal_exact in [("both", True, True), (True, True, True), ("depth", True, False),
                                             ("normal", False, True), (False, False, False)]:
        sc = load_study_scene("scannet_like_tiny", "tiny", which)
        assert np.array_equal(sc.mono_depth, sc.gt_depth if depth_exact else shipped.mono_depth), which
        assert np.array_equal(sc.mono_normal, sc.gt_normal if normal_exact else shipped.mono_normal), which
    with pytest.raises(ValueError, match="exact priors must be one of"):
        exact_priors_choice("colour")


def test_parse_sweep():
    assert parse_sweep("lr=1e-3,2e-3") == ("lr", [1e-3, 2e-3])
    assert parse_sweep("inside_out=true,false")[1] == [True, False]
    assert parse_sweep(None) == (None, [None])


@pytest.mark.slow
def test_study_cli_writes_curves_with_diagnostics(tmp_path):
    out = tmp_path / "study"
    rc = main(["study", "convergence", "monosdf", "scannet_like_tiny", "--scale", "tiny", "--seeds", "0", "--snapshots", "2",
               "--exact-priors", "--workers", "1", "--set", "iterations=8", "rays_per_batch=64", "mesh_resolution=32",
               "--sweep", "appearance_dim=0,8", "--out", str(out)])
    assert rc == 0
    df = pd.read_csv(out / "study.csv", dtype={"value": str})
    assert len(df) == 4 and set(df["value"]) == {"0", "8"}
    assert {"fscore", "acc", "comp", "beta", "loss_color", "depth_err_median", "iterations", "seconds"} <= set(df.columns)
    assert list(df["iterations"][:2]) == [4, 8]
    assert (out / "study.png").stat().st_size > 1000
    md = (out / "study.md").read_text()
    assert "appearance_dim" in md and "flat" in md
    assert "(tiny, exact priors, smoke test: not a result)" in md  # tiny: the checks below are no verdict
    meshes = sorted(p.name for p in (out / "meshes").glob("*.ply"))  # every snapshot's mesh of every run, to look at
    assert meshes == ["appearance_dim=0_seed0.ply", "appearance_dim=0_seed0_it4.ply",
                      "appearance_dim=8_seed0.ply", "appearance_dim=8_seed0_it4.ply"]


def test_study_bad_key_is_one_clear_error(tmp_path, capsys):
    rc = main(["study", "convergence", "monosdf", "scannet_like_tiny", "--scale", "tiny", "--seeds", "0",
               "--sweep", "no_such_key=1,2", "--out", str(tmp_path / "x")])
    assert rc == 2
    assert "no_such_key" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


@pytest.mark.slow
def test_stop_at_trains_only_the_early_part_of_the_same_schedule(tmp_path):
    out = tmp_path / "screen"
    rc = main(["study", "convergence", "monosdf", "scannet_like_tiny", "--scale", "tiny", "--seeds", "0", "--snapshots", "4",
               "--stop-at", "0.5", "--exact-priors", "--workers", "1", "--set", "iterations=8", "rays_per_batch=64",
               "mesh_resolution=32", "--out", str(out)])
    assert rc == 0
    df = pd.read_csv(out / "study.csv")
    assert list(df["iterations"]) == [2, 4] and list(df["fraction"]) == [0.25, 0.5]
    assert "stopped at 50%" in (out / "study.md").read_text()
    assert main(["study", "convergence", "monosdf", "scannet_like_tiny", "--stop-at", "0.01", "--out", str(out)]) == 2
