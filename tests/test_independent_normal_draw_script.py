"""scripts/independent_normal_draw.py: the normal prior of an independent draw of a recipe's error chain
(``make_scene(..., effect_stream=k)``)."""

from __future__ import annotations

import numpy as np

from bench.data.datasets import recipe_path
from bench.data.synth.make import make_scene
from bench.data.synth.recipe import load_recipe


def _angles_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    valid = (np.linalg.norm(a, axis=-1) > 0.5) & (np.linalg.norm(b, axis=-1) > 0.5)
    return np.degrees(np.arccos(np.clip((a[valid] * b[valid]).sum(-1), -1.0, 1.0)))


def test_an_independent_effect_stream_keeps_the_geometry_and_redraws_the_normal_errors(load_script):
    shipped, _ = make_scene(load_recipe(recipe_path("scannet_like_0")), scale="tiny")
    other_scene, _ = make_scene(load_recipe(recipe_path("scannet_like_0")), scale="tiny", effect_stream=1)
    for field in ("gt_depth", "gt_normal", "gt_instance", "cam_to_world", "intrinsics"):  # the same scene, bit for bit
        np.testing.assert_array_equal(getattr(other_scene, field), getattr(shipped, field))
    scene, _, other = load_script("independent_normal_draw").independent_normals("scannet_like_0", "tiny", 1)
    np.testing.assert_array_equal(scene.mono_normal, shipped.mono_normal)  # the shipped scene it writes
    np.testing.assert_array_equal(other, other_scene.mono_normal)
    gt = np.asarray(shipped.gt_normal)
    err_shipped, err_other = np.median(_angles_deg(shipped.mono_normal, gt)), np.median(_angles_deg(other, gt))
    # same error size (within a half: the calibrated profiles draw each view's difficulty, and the tiny
    # scale has few views) ...
    assert err_shipped > 3.0 and abs(err_other - err_shipped) < 0.5 * err_shipped
    assert np.median(_angles_deg(other, shipped.mono_normal)) > 3.0  # ... but not the same errors
