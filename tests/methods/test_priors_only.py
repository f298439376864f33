"""The "priors only" reference row: TSDF fusion of the mono prior aligned per view to GT (oracle_tsdf with
``depth_source: prior_aligned``)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from bench.data.errors import BenchInputError
from methods.oracle_tsdf import fusion_depth


def test_an_affine_prior_aligns_back_to_gt_exactly(tiny_scene):
    views = tiny_scene.view_indices("train")[:4]
    gt = tiny_scene.gt_depth
    scales = np.array([0.5, 2.0, 1.3, 0.8])[:, None, None]
    prior = np.where(gt > 0, gt * np.resize(scales, (len(gt), 1, 1)) + 0.25, 0.0).astype(np.float32)
    scene = dataclasses.replace(tiny_scene, mono_depth=prior)
    out = fusion_depth(scene, views, "prior_aligned")
    np.testing.assert_allclose(out, gt[views], atol=2e-4)


def test_shipped_prior_differs_from_gt_and_stays_finite(tiny_scene):
    views = tiny_scene.view_indices("train")
    out = fusion_depth(tiny_scene, views, "prior_aligned")
    gt = tiny_scene.gt_depth[views]
    assert np.isfinite(out).all() and (out >= 0).all()
    err = np.abs(out - gt)[(gt > 0) & (out > 0)]
    assert 0.005 < np.median(err) < 0.5  # the simulated prior is wrong by centimetres, not exact and not garbage


def test_constant_prior_view_is_skipped_and_bad_source_is_an_error(tiny_scene):
    views = tiny_scene.view_indices("train")[:2]
    prior = tiny_scene.mono_depth.copy()
    prior[views[0]] = 1.0
    out = fusion_depth(dataclasses.replace(tiny_scene, mono_depth=prior), views, "prior_aligned")
    assert (out[0] == 0).all() and (out[1] > 0).any()
    with pytest.raises(BenchInputError, match="depth_source"):
        fusion_depth(tiny_scene, views, "mono")


@pytest.mark.slow
def test_priors_only_row_is_below_the_oracle(tiny_scene):
    from bench.evaluate import evaluate_snapshot
    from methods.oracle_tsdf import OracleTSDF
    from methods.registry import method_config

    res = {}
    for source in ("gt", "prior_aligned"):
        cfg = method_config("oracle_tsdf", "tiny", {"depth_source": source, "fractions": [1.0]})
        art = OracleTSDF().fit(tiny_scene, cfg, seed=0)
        res[source] = evaluate_snapshot(art.final, tiny_scene, "scannet", "tiny")
    assert res["gt"]["fscore"] > 0.9
    assert 0.05 < res["prior_aligned"]["fscore"] < res["gt"]["fscore"]
