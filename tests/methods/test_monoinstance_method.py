"""MonoInstance on the MonoSDF base: the modules as configs, sampler and mask constraint behave, fit runs."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch

from methods.monoinstance.method import certainty_weights
from methods.monoinstance.sampling import GuidedSampler
from methods.registry import method_config, typed_method_config


def test_ablation_rows_are_configs_of_one_method():
    base = method_config("monoinstance", "tiny", {"uncertainty": False, "guided_sampling": False, "mask_constraint": False})
    full = method_config("monoinstance", "tiny")
    mono = method_config("monosdf", "tiny")
    assert set(mono) <= set(base)  # inherits every MonoSDF parameter
    assert {k for k in full if full[k] != base[k]} == {"uncertainty", "guided_sampling", "mask_constraint"}


def test_certainty_cutoff_only_on_foreground_instances():
    U = np.array([[[0.9, 0.9, 0.1, 0.0]]], dtype=np.float32)
    ids = np.array([[[1, 2, 1, 0]]])
    c = certainty_weights(U, ids, {1: False, 2: True}, cutoff=0.2)
    np.testing.assert_allclose(c[0, 0], [0.0, 0.1, 0.9, 1.0], atol=1e-6)


def test_guided_sampler_allocates_by_area_and_prefers_uncertain_pixels():
    ids = np.zeros((1, 20, 20), dtype=np.int64)
    ids[0, :10, :10] = 1  # area 100, foreground
    ids[0, 10:, 10:14] = 2  # area 40, foreground
    ids[0, 15:, :5] = 3  # background instance
    U = np.zeros((1, 20, 20), dtype=np.float32)
    U[0, :5, :10] = 1.0  # upper half of instance 1 is uncertain
    s = GuidedSampler(ids, {1: False, 2: False, 3: True}, U, bg_dilation_px=1)
    pix = s(0, 4000, torch.Generator().manual_seed(0)).numpy()
    flat = ids.reshape(-1)[pix]
    assert len(pix) == 4000
    assert abs((np.isin(flat, [1, 2])).mean() - 0.75) < 1e-3  # 3/4 of the rays on foreground instances
    assert abs((flat == 1).sum() / (flat == 2).sum() - 100 / 40) < 0.1  # share proportional to area
    rows = pix[flat == 1] // 20
    assert (rows < 5).mean() > 0.9  # p ~ U + 0.05: uncertain half gets 1.05 / 1.10 of the mass
    assert set(np.unique(flat[~np.isin(flat, [1, 2])])) <= {0, 3}
    again = s(0, 4000, torch.Generator().manual_seed(0)).numpy()
    np.testing.assert_array_equal(pix, again)  # deterministic


@pytest.mark.slow
def test_monoinstance_fit_runs_two_stages_with_all_modules(tiny_scene):
    from methods.monoinstance.method import MonoInstance

    cfg = method_config("monoinstance", "tiny", {"iterations": 12, "rays_per_batch": 64, "mesh_resolution": 24})
    art = MonoInstance().fit(tiny_scene, cfg, seed=0)
    assert art.iterations == 12
    assert {"train", "mesh", "render_ref_depth", "segmentation", "uncertainty"} <= set(art.timings)
    assert art.uncertainty is not None and np.isfinite(art.uncertainty).all()
    assert 0.0 <= art.uncertainty.min() and art.uncertainty.max() <= 1.0
    assert "unc_mean_thin" in art.extra and "unc_mean_planar" in art.extra
    assert all(len(s.mesh.faces) > 0 for s in art.snapshots)


def test_mask_constraint_loss_is_finite_and_reaches_the_sdf(tiny_scene):
    from methods.monoinstance.mask_constraint import MaskConstraint
    from methods.monosdf.trainer import MonoSDFTrainer

    cfg = typed_method_config("monoinstance", "tiny", {"rays_per_batch": 64})
    tr = MonoSDFTrainer(tiny_scene, cfg, seed=0)
    ids = tiny_scene.gt_instance[tr.views]
    bg = {i: info.is_background for i, info in tiny_scene.instances.items()}
    untrusted = np.isin(ids, [i for i, b in bg.items() if not b])  # every foreground ray is "untrusted"
    mc = MaskConstraint(tr, ids, bg, untrusted, replace(cfg, mask_max_ray_dist=1.0, mask_min_views=2))
    assert mc.sources, "no instance found nearby views"
    (view, k), _ = next(iter(mc.sources.items()))
    pixels = torch.from_numpy(np.flatnonzero(ids[view] == k)[:64])
    out = tr.render_pixels(view, pixels)
    terms = mc(tr, view, pixels, out)
    weight, loss = terms["mask"]
    assert weight == pytest.approx(0.4) and torch.isfinite(loss) and float(loss.detach()) > 0
    loss.backward()
    grads = [p.grad for p in tr.sdf.parameters() if p.grad is not None]
    assert grads and all(torch.isfinite(g).all() for g in grads)
    assert sum(float(g.abs().sum()) for g in grads) > 0  # the loss moves the geometry (through the weights)


def test_mask_constraint_options_and_diagnostics(tiny_scene):
    """The official code's normalisation never exceeds ours (its denominators count empty sources and
    instances too), a lower mask-hit threshold counts at least as many rays, and the diagnostics describe
    the counted rays (rays, instances, sum of w * valid, reference - warped colour)."""
    from methods.monoinstance.mask_constraint import MaskConstraint
    from methods.monosdf.trainer import MonoSDFTrainer

    cfg = typed_method_config("monoinstance", "tiny", {"rays_per_batch": 64})
    tr = MonoSDFTrainer(tiny_scene, cfg, seed=0)
    ids = tiny_scene.gt_instance[tr.views]
    bg = {i: info.is_background for i, info in tiny_scene.instances.items()}
    untrusted = np.isin(ids, [i for i, b in bg.items() if not b])
    base = replace(cfg, mask_max_ray_dist=1.0, mask_min_views=2, mask_source_choice="nearest")  # the same sources in every call
    view = next(iter(MaskConstraint(tr, ids, bg, untrusted, base).sources))[0]
    pixels = torch.randperm(ids[view].size, generator=torch.Generator().manual_seed(0))[:256]
    with torch.no_grad():
        out = tr.render_pixels(view, pixels)
    results = {}
    for norm in ("code", "ours"):
        for hit in (0.0, 0.5):
            mc = MaskConstraint(tr, ids, bg, untrusted, replace(base, mask_normalisation=norm, mask_hit_threshold=hit))
            loss = float(mc(tr, view, pixels, out)["mask"][1])
            results[norm, hit] = (loss, mc.diagnostics())
    for hit in (0.0, 0.5):
        assert results["code", hit][0] <= results["ours", hit][0] + 1e-6
    diag0, diag5 = results["code", 0.0][1], results["code", 0.5][1]
    assert diag0["mask_rays"] >= diag5["mask_rays"] > 0
    assert 0 < diag0["mask_instances"] <= diag0["mask_instances_valid"]
    assert diag0["mask_untrusted_rays"] > 0
    assert 0.0 < diag0["mask_wvalid_mean"] <= 1.0 + 1e-5 and -1.0 <= diag0["mask_color_gap"] <= 1.0
    assert mc.diagnostics() == {}  # reset by the call above
    ren = MaskConstraint(tr, ids, bg, untrusted, replace(base, mask_renormalise=True))
    float(ren(tr, view, pixels, out)["mask"][1])
    gap = ren.diagnostics()["mask_color_gap"]
    assert abs(gap) < abs(diag0["mask_color_gap"]) + 1e-6 or abs(gap) < 0.05  # the darkening bias is gone
    with pytest.raises(ValueError, match="mask_normalisation"):
        typed_method_config("monoinstance", "tiny", {"mask_normalisation": "paper"})


def test_mask_sources_are_drawn_among_the_valid_views_and_rays_come_from_eroded_masks(tiny_scene):
    from methods.monoinstance.mask_constraint import MaskConstraint, eroded_instances
    from methods.monosdf.trainer import MonoSDFTrainer

    ids = np.zeros((1, 6, 7), dtype=np.int64)
    ids[0, 1:4, 1:5] = 3  # a 3 x 4 block
    ids[0, :, 5:7] = 5  # two full-height columns on the image border: the border does not erode (cv2 style)
    er = eroded_instances(ids, 2)
    assert (er[0] == 3).sum() == 2 * 3 and (er[0] == 5).sum() == 6 and set(np.unique(er)) <= {0, 3, 5}
    assert (eroded_instances(ids, 0) == ids).all()

    cfg = typed_method_config("monoinstance", "tiny", {"rays_per_batch": 64})
    tr = MonoSDFTrainer(tiny_scene, cfg, seed=0)
    tids = tiny_scene.gt_instance[tr.views]
    bg = {i: info.is_background for i, info in tiny_scene.instances.items()}
    untrusted = np.isin(tids, [i for i, b in bg.items() if not b])
    mc = MaskConstraint(tr, tids, bg, untrusted, replace(cfg, mask_max_ray_dist=1.0, mask_min_views=2, mask_n_source=2))
    key = max(mc.candidates, key=lambda kv: len(mc.candidates[kv]))
    draws = [tuple(mc._choose_sources(*key, tr.gen)) for _ in range(40)]
    assert all(len(d) == 2 and set(d) <= set(mc.candidates[key]) for d in draws)
    if len(mc.candidates[key]) > 2:
        assert len(set(draws)) > 1  # drawn anew every step, not the fixed nearest pair


def test_final_phase_learning_rate_holds_every_group_at_its_factor(tiny_scene):
    """The code-only final phase trains at a fixed network lr (1e-5 in the release): every optimiser group
    keeps its factor to the network lr (grid x grid_lr_factor), no decay."""
    from methods.monosdf.trainer import MonoSDFTrainer

    cfg = typed_method_config("monoinstance", "tiny", {"rays_per_batch": 32})
    tr = MonoSDFTrainer(tiny_scene, cfg, seed=0)
    tr.step()
    tr.fixed_lr = cfg.final_phase_lr
    for _ in range(2):
        tr.step()
        lrs = [g["lr"] for g in tr.optim.param_groups]
        assert lrs[0] == pytest.approx(1e-5 * cfg.grid_lr_factor) and lrs[1] == pytest.approx(1e-5)
