"""scripts/independent_normal_draw.py: the normal prior of an independent draw of a recipe's error chain."""

from __future__ import annotations

import numpy as np

from bench.data.datasets import recipe_path
from bench.data.synth.make import make_scene
from bench.data.synth.recipe import load_recipe


def _angles_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    valid = (np.linalg.norm(a, axis=-1) > 0.5) & (np.linalg.norm(b, axis=-1) > 0.5)
    return np.degrees(np.arccos(np.clip((a[valid] * b[valid]).sum(-1), -1.0, 1.0)))


def test_the_shipped_stream_reproduces_the_shipped_normals_and_another_stream_does_not(load_script):
    recipe = load_recipe(recipe_path("scannet_like_0"))
    shipped, _ = make_scene(recipe, scale="tiny")
    script = load_script("independent_normal_draw")
    same = script.chain_normals(recipe, "tiny", [recipe.seed, 1])
    np.testing.assert_array_equal(same, shipped.mono_normal)  # the chain and its stream, bit for bit
    other = script.chain_normals(recipe, "tiny", [recipe.seed, 1, 1])
    gt = np.asarray(shipped.gt_normal)
    err_shipped, err_other = np.median(_angles_deg(shipped.mono_normal, gt)), np.median(_angles_deg(other, gt))
    assert err_shipped > 3.0 and abs(err_other - err_shipped) < 0.3 * err_shipped  # same error size ...
    assert np.median(_angles_deg(other, shipped.mono_normal)) > 3.0  # ... but not the same errors
