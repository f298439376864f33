"""Gaussian variants: losses, densification strategy, configs, and tiny end-to-end runs."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import yaml

from methods.gaussians import losses
from methods.gaussians.model import init_params
from methods.gaussians.strategy import DefaultStrategy
from methods.registry import CONFIG_DIR, available_methods, get_method, method_config

VARIANT_KEYS = {"depth_loss", "uncertainty", "mask_constraint"}


def test_registered_as_one_family():
    assert {"gs3d", "fsgs", "monoinstance_gs"} <= set(available_methods())
    from methods.gaussians.methods import GaussianSplatting

    for name in ("gs3d", "fsgs", "monoinstance_gs"):
        assert isinstance(get_method(name), GaussianSplatting)


def test_configs_differ_only_in_variant_keys():
    """One preset (gs3d.yaml) for the family: the variants inherit it and declare only their switches."""
    for name in ("fsgs", "monoinstance_gs"):
        raw = yaml.safe_load((CONFIG_DIR / f"{name}.yaml").read_text())
        assert raw["base"] == "gs3d" and set(raw["defaults"]) <= VARIANT_KEYS, name
        assert not any(raw["scales"].values()), name  # no scale preset of its own
        for scale in ("tiny", "small", "medium", "large"):
            mine, base = method_config(name, scale), method_config("gs3d", scale)
            assert set(mine) == set(base) and {k for k in mine if mine[k] != base[k]} <= VARIANT_KEYS, (name, scale)
    assert method_config("fsgs", "small")["depth_loss"] == "pearson" and not method_config("fsgs", "small")["uncertainty"]
    assert method_config("monoinstance_gs", "small")["uncertainty"] and method_config("monoinstance_gs", "small")["mask_constraint"]


def test_pearson_is_affine_invariant_and_weighted():
    g = torch.Generator().manual_seed(0)
    d = torch.rand(10, 12, generator=g) + 1.0
    assert losses.pearson_depth_loss(d, 3.0 * d + 2.0).item() == pytest.approx(0.0, abs=1e-5)
    assert losses.pearson_depth_loss(d, -d + 5.0).item() == pytest.approx(2.0, abs=1e-5)
    prior = 2.0 * d + 1.0
    prior[:, :6] = torch.rand(10, 6, generator=g) + 1.0  # corrupt half
    w = torch.ones_like(d)
    w[:, :6] = 0.0
    assert losses.pearson_depth_loss(d, prior, w).item() == pytest.approx(0.0, abs=1e-5)
    assert losses.pearson_depth_loss(d, prior).item() > 0.05
    assert losses.pearson_depth_loss(d, prior, torch.zeros_like(d)).item() == 0.0
    invalid = prior.clone()
    invalid[:, :6] = 0.0  # prior 0 = invalid pixels are ignored
    assert losses.pearson_depth_loss(d, invalid).item() == pytest.approx(0.0, abs=1e-5)


def test_ssim_identical_is_one():
    x = torch.rand(20, 20, 3, generator=torch.Generator().manual_seed(1))
    assert losses.ssim_map(x, x).mean().item() == pytest.approx(1.0, abs=1e-6)
    assert losses.photometric_loss(x, x).item() == pytest.approx(0.0, abs=1e-6)


def test_mask_constraint_zero_inside_positive_outside_with_gradient():
    from scipy.ndimage import distance_transform_edt

    W = H = 20
    K = torch.tensor([[20.0, 0, 9.5], [0, 20.0, 9.5], [0, 0, 1]])
    vm = torch.eye(4)
    mask = np.zeros((H, W), bool)
    mask[5:15, 5:15] = True
    dist = {(1, 3): torch.tensor(distance_transform_edt(~mask), dtype=torch.float32)}
    inside = torch.tensor([[0.0, 0.0, 2.0]], requires_grad=True)  # projects to (9.5, 9.5): in the mask
    loss, n = losses.mask_constraint_loss(inside, torch.tensor([3]), dist, [(1, K, vm)], W, H)
    assert n == 1 and loss.item() == 0.0
    outside = torch.tensor([[1.5, 0.0, 2.0]], requires_grad=True)  # u = 24.5: outside the image -> not counted
    loss, n = losses.mask_constraint_loss(outside, torch.tensor([3]), dist, [(1, K, vm)], W, H)
    assert n == 0
    off = torch.tensor([[0.8, 0.0, 2.0]], requires_grad=True)  # u = 17.5: inside the image, outside the mask
    loss, n = losses.mask_constraint_loss(off, torch.tensor([3]), dist, [(1, K, vm)], W, H)
    assert n == 1 and loss.item() == pytest.approx(3.5 / W, abs=0.03)
    loss.backward()
    assert off.grad[0, 0] > 0  # moving the point towards the mask lowers the penalty
    loss, n = losses.mask_constraint_loss(off, torch.tensor([7]), dist, [(1, K, vm)], W, H)  # instance absent there
    assert n == 0


def _params(n=50, seed=0):
    rng = np.random.default_rng(seed)
    return init_params(rng.normal(size=(n, 3)) + [0, 0, 3], rng.uniform(size=(n, 3)).astype(np.float32), 0.1)


def test_strategy_grows_prunes_and_keeps_adam_state_aligned():
    params = _params()
    opts = {k: torch.optim.Adam([v], lr=1e-3) for k, v in params.items()}
    loss = sum((v ** 2).sum() for v in params.values())
    loss.backward()
    for o in opts.values():
        o.step()
    st = DefaultStrategy(grad_threshold=0.0, refine_start=1, refine_every=1, refine_stop=10, max_gaussians=80, scene_extent=10.0, percent_dense=0.01)
    with torch.no_grad():
        params["opacities"][:5] = -20.0  # will be pruned
    m2d = torch.zeros(50, 2, requires_grad=True)
    m2d.grad = torch.ones(50, 2)
    st.step_post_backward(params, opts, 0, m2d, torch.ones(50), 16, 12, torch.Generator().manual_seed(0))
    n = params["means"].shape[0]
    assert st.n_prune == 5 and st.n_clone + st.n_split > 0 and n <= 80
    for k, v in params.items():
        assert v.is_leaf and v.requires_grad
        state = opts[k].state[v]
        assert state["exp_avg"].shape == v.shape and state["exp_avg_sq"].shape == v.shape
        assert opts[k].param_groups[0]["params"][0] is v


@pytest.mark.slow
@pytest.mark.parametrize("name", ["gs3d", "fsgs", "monoinstance_gs"])
def test_tiny_end_to_end(llff_tiny_scene, name):
    cfg = method_config(name, "tiny", {"iterations": 24, "refine_start": 4, "refine_every": 4, "sh_increase_every": 8,
                                       "init_max_points": 300, "init_random": 100, "init_depths": 8})
    art = get_method(name).fit(llff_tiny_scene, cfg, seed=0)
    test = llff_tiny_scene.view_indices("test")
    assert [s.fraction for s in art.snapshots] == [0.25, 0.5, 1.0]
    r = art.final.renders
    assert r.shape == (len(test), llff_tiny_scene.height, llff_tiny_scene.width, 3) and r.dtype == np.float32
    assert np.isfinite(r).all() and r.min() >= 0 and r.max() <= 1
    assert {"init", "train", "uncertainty", "render"} <= set(art.timings)
    if name == "monoinstance_gs":
        assert art.uncertainty is not None and art.uncertainty[test].max() == 0  # never sees test views
        assert art.timings["uncertainty"] > 0


@pytest.mark.slow
def test_deterministic_for_a_seed(llff_tiny_scene):
    cfg = method_config("fsgs", "tiny", {"iterations": 10, "init_max_points": 200, "init_random": 50, "init_depths": 8})
    a = get_method("fsgs").fit(llff_tiny_scene, cfg, seed=3).final.renders
    b = get_method("fsgs").fit(llff_tiny_scene, cfg, seed=3).final.renders
    assert np.allclose(a, b, atol=1e-5)


def test_mask_constraint_without_uncertainty_is_an_error():
    """Caught when the config is resolved, before any job runs (the typed config's check)."""
    with pytest.raises(ValueError, match="mask_constraint needs uncertainty"):
        method_config("gs3d", "tiny", {"mask_constraint": True, "iterations": 4})
