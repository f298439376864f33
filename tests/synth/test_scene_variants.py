"""Scene variants (a table group's ``effects``): the same recipe made with other effect parameters,
e.g. another simulated prior profile for Table 5."""

from __future__ import annotations

import numpy as np
import pytest

from bench.data.datasets import load_dataset, recipe_hash, recipe_path
from bench.data.errors import BenchInputError
from bench.data.synth.recipe import load_recipe, with_effect_overrides

SCENE = "scannet_like_tiny"


def test_override_changes_only_the_named_effect():
    recipe = load_recipe(recipe_path(SCENE))
    variant = with_effect_overrides(recipe, {"prior_profile": {"profile": "sim-geowizard"}})
    assert [e for e in variant.effects if e["name"] == "prior_profile"][0]["profile"] == "sim-geowizard"
    assert [e for e in variant.effects if e["name"] != "prior_profile"] == [e for e in recipe.effects if e["name"] != "prior_profile"]
    assert recipe.effects != variant.effects  # the recipe itself is untouched


def test_unknown_effect_is_a_clear_error():
    recipe = load_recipe(recipe_path(SCENE))
    with pytest.raises(BenchInputError, match="no effect 'motion_blur' to override"):
        with_effect_overrides(recipe, {"motion_blur": {"strength": 1}})


def test_variant_hash_and_dataset(tmp_path):
    path = recipe_path(SCENE)
    current = [e for e in load_recipe(path).effects if e["name"] == "prior_profile"][0]["profile"]
    assert recipe_hash(path, {"prior_profile": {"profile": current}}) == recipe_hash(path)  # no-op: shared
    other = {"prior_profile": {"profile": "sim-geowizard" if current != "sim-geowizard" else "sim-omnidata"}}
    assert recipe_hash(path, other) != recipe_hash(path)
    plain = load_dataset(SCENE, "tiny", tmp_path)
    varied = load_dataset(SCENE, "tiny", tmp_path, effects=other)
    np.testing.assert_array_equal(plain.gt_depth, varied.gt_depth)  # same geometry and cameras
    assert not np.allclose(plain.mono_depth, varied.mono_depth)      # another prior
    assert len(list(tmp_path.iterdir())) == 2
