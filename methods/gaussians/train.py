"""Training loop of the Gaussian variants (3DGS / FSGS-style / MonoInstance-GS), driven by one config dict.

Schedule (``iterations`` steps, one random training view per step):

1. init: points from the training views (:func:`methods.gaussians.model.init_points_from_views`).
2. steps ``[0, stage1)``: photometric loss (+ FSGS Pearson depth loss when ``depth_loss: pearson``).
   With ``uncertainty: false`` this is the whole schedule.
3. ``uncertainty: true`` only, at ``stage1 = round(stage1_fraction x iterations)``: render the
   expected z-depth of the training views, run the shared MonoInstance estimator
   (``methods.monoinstance.run_uncertainty_stage``) on a Scene restricted to the training
   views (the LLFF protocol lets a method see only those; test images never reach it), then train the
   remaining steps with the depth loss weighted per pixel by ``1 - U`` (0 where ``U > u_cut`` on
   instance pixels, as the official code) and, with ``mask_constraint: true``, the supplementary's
   instance-mask constraint on pixels with ``U > mask_u_threshold``.

Adam with per-parameter learning rates (3DGS's, ``lr_*`` keys); the means' rate decays exponentially
from ``lr_means`` to ``lr_means_final`` (x scene extent); densification by :class:`DefaultStrategy`.
Snapshots (renders of the TEST views) at ``fractions`` of the schedule.
"""

from __future__ import annotations

import dataclasses
import math
import time
from typing import Any, Callable, cast

import numpy as np
import torch

from bench.data.scene import Scene
from methods.base import Artifacts, Snapshot
from methods.cpp_build import OwnClock
from methods.gaussians import losses
from methods.gaussians.config import GaussianConfig
from methods.gaussians.model import init_params, init_points_from_views, render
from methods.gaussians.strategy import DefaultStrategy
from metrics.image import psnr

PARAM_LR_KEYS = {"means": "lr_means", "scales": "lr_scales", "quats": "lr_quats", "opacities": "lr_opacities", "sh0": "lr_sh0", "shN": "lr_shN"}


def restrict_scene(scene: Scene, views: np.ndarray) -> Scene:
    """A copy of ``scene`` holding only ``views`` (every per-view array indexed; splits dropped)."""
    per_view = ("images", "intrinsics", "cam_to_world", "mono_depth", "mono_normal", "seg_masks", "gt_depth", "gt_normal", "gt_instance")
    kw: dict[str, Any] = {f: (getattr(scene, f)[views] if getattr(scene, f) is not None else None) for f in per_view}
    if scene.seg_background is not None:
        kw["seg_background"] = [scene.seg_background[int(i)] for i in views]
    kw["splits"] = {"train": np.arange(len(views))}
    return dataclasses.replace(scene, **kw)


def _bounds(scene: Scene, views: np.ndarray) -> tuple[float, float]:
    b = scene.metadata.get("llff_bounds")
    if b is not None:
        b = np.asarray(b, dtype=np.float64)[views]
        return float(b[:, 0].min()), float(b[:, 1].max())
    raise ValueError(f"scene {scene.name!r} has no LLFF near/far bounds (metadata['llff_bounds'])")


def train_gaussians(scene: Scene, cfg: GaussianConfig, seed: int, progress: Callable[[float, str], None] | None = None) -> Artifacts:
    """Fit the Gaussians of ``scene``'s training views and render its test views (see the module docstring)."""
    if cfg.num_threads:
        torch.set_num_threads(cfg.num_threads)
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    trng = torch.Generator().manual_seed(seed)
    timings: dict[str, float] = {"init": 0.0, "train": 0.0, "uncertainty": 0.0, "render": 0.0}
    train = scene.view_indices("train")
    test = scene.view_indices("test")
    H, W = scene.height, scene.width
    near, far = _bounds(scene, train)

    init_clock = OwnClock()
    pts, cols, counts = init_points_from_views(scene.images[train], scene.intrinsics[train], scene.cam_to_world[train], near, far,
                                               n_depths=cfg.init_depths, n_random=cfg.init_random,
                                               max_sweep_points=cfg.init_max_points, rng=rng,
                                               cost_ratio=cfg.init_cost_ratio, cost=cfg.init_cost,
                                               all_views=cfg.init_all_views)
    centres = scene.cam_to_world[train][:, :3, 3]
    # footprint cap: sigma <= init_max_px pixels at the point's distance from the nearest training camera
    cam_dist = np.linalg.norm(pts[:, None, :] - centres[None], axis=-1).min(1)
    focal = float(scene.intrinsics[train][:, 0, 0].mean())
    params = init_params(pts, cols, cfg.init_opacity, max_scale=cfg.init_max_px * cam_dist / focal)
    extent = 1.1 * float(np.linalg.norm(centres - centres.mean(0), axis=1).max())
    extent = max(extent, 0.05 * far)  # forward-facing rigs have a tiny baseline: keep a depth-related floor
    lr_scale_means = extent
    optimizers = {k: torch.optim.Adam([params[k]], lr=float(getattr(cfg, v)) * (lr_scale_means if k == "means" else 1.0), eps=1e-15)
                  for k, v in PARAM_LR_KEYS.items()}
    iters = cfg.iterations
    strategy = DefaultStrategy(grad_threshold=cfg.densify_grad_threshold, percent_dense=cfg.percent_dense,
                               refine_start=cfg.refine_start, refine_stop=int(cfg.refine_stop_fraction * iters),
                               refine_every=cfg.refine_every, reset_every=cfg.opacity_reset_every,
                               prune_opacity=cfg.prune_opacity, max_gaussians=cfg.max_gaussians, scene_extent=extent)
    viewmats = torch.tensor(np.linalg.inv(scene.cam_to_world), dtype=torch.float32)
    Ks = torch.tensor(scene.intrinsics, dtype=torch.float32)
    images = torch.tensor(scene.images, dtype=torch.float32)
    mono = torch.tensor(scene.mono_depth, dtype=torch.float32) if scene.mono_depth is not None else None
    bg = torch.zeros(3)
    rkw: dict[str, Any] = {"near": cfg.near, "kernel": cfg.raster_kernel}
    timings["init"] = init_clock.seconds()

    depth_loss = cfg.depth_loss  # none | pearson (checked by GaussianConfig)
    use_unc = cfg.uncertainty
    if (depth_loss != "none" or use_unc) and mono is None:
        raise ValueError(f"scene {scene.name!r} has no monocular depth prior but depth_loss={depth_loss!r}")
    stage1 = int(round(cfg.stage1_fraction * iters)) if use_unc else iters
    fractions = sorted(float(f) for f in cfg.fractions)
    snap_steps = {max(1, int(round(f * iters))): f for f in fractions}
    sh_degree = cfg.sh_degree
    sh_every = cfg.sh_increase_every
    lr0, lr1 = cfg.lr_means * lr_scale_means, cfg.lr_means_final * lr_scale_means

    depth_weights: dict[int, torch.Tensor] = {}
    mask_data: dict[str, Any] | None = None
    unc_full: np.ndarray | None = None
    extra: dict[str, Any] = {"init_points": counts}
    snapshots: list[Snapshot] = []
    train_seconds = 0.0
    order = rng.permutation(len(train))
    k_order = 0
    loss_hist: list[float] = []
    for step in range(iters):
        if step == stage1 and use_unc:
            t = time.perf_counter()
            depth_weights, mask_data, unc_full, q = _uncertainty_stage(scene, train, params, viewmats, Ks, W, H, min(sh_degree, step // sh_every), bg, rkw, cfg, seed)
            extra["uncertainty_quality"] = q
            timings["uncertainty"] += time.perf_counter() - t
        step_clock = OwnClock()  # the step's own work: a first-use kernel build inside it is not booked
        if k_order >= len(order):
            order, k_order = rng.permutation(len(train)), 0
        vi = int(train[order[k_order]])
        k_order += 1
        frac = step / max(iters - 1, 1)
        for g in optimizers["means"].param_groups:
            g["lr"] = math.exp(math.log(lr0) * (1 - frac) + math.log(lr1) * frac)
        deg = min(sh_degree, step // sh_every)
        out = render(params, viewmats[vi], Ks[vi], W, H, deg, bg, **rkw)
        m2d = out["proj"].means2d
        m2d.retain_grad()
        img = out["color"]
        loss = losses.photometric_loss(img, images[vi], cfg.lambda_dssim)
        if depth_loss == "pearson":
            wmap = depth_weights.get(vi) if step >= stage1 else None
            # mono is not None here: a missing prior with depth_loss != "none" raised before the loop
            loss = loss + cfg.depth_weight * losses.pearson_depth_loss(out["depth"], cast(torch.Tensor, mono)[vi], wmap)
        if mask_data is not None and step >= stage1 and cfg.mask_weight > 0:
            loss = loss + cfg.mask_weight * _mask_loss(out, vi, mask_data, viewmats, Ks, W, H)
        loss.backward()
        strategy.step_post_backward(params, optimizers, step, m2d, out["proj"].radii, W, H, trng)
        for name, opt in optimizers.items():
            if params[name].grad is not None or any(p.grad is not None for p in opt.param_groups[0]["params"]):
                opt.step()
            opt.zero_grad(set_to_none=True)
        if not torch.isfinite(loss):
            raise FloatingPointError(f"non-finite loss at step {step}")
        loss_hist.append(float(loss.detach()))
        train_seconds += step_clock.seconds()
        if progress and step % 25 == 0:
            progress(step / iters, f"step {step}/{iters} loss {float(loss):.4f} N={params['means'].shape[0]}")
        if step + 1 in snap_steps:
            t = time.perf_counter()
            with torch.no_grad():
                outs = [render(params, viewmats[v], Ks[v], W, H, deg, bg, **rkw) for v in test]
                renders = np.stack([o["color"].clamp(0, 1).numpy() for o in outs])
                depths = np.stack([torch.where(o["alpha"] >= 0.5, o["depth"] / o["alpha"].clamp_min(1e-6), torch.zeros_like(o["alpha"])).numpy()
                                   for o in outs])  # expected z-depth where the view is covered (as _render_depths)
                train_renders = np.stack([render(params, viewmats[v], Ks[v], W, H, deg, bg, **rkw)["color"].clamp(0, 1).numpy() for v in train])
            # few-shot overfitting, measured: PSNR on the training views beside the test views' (docs/tables.md "Table 3 scenes")
            extra.setdefault("train_psnr", []).append(float(psnr(train_renders, scene.images[train]).mean))
            timings["render"] += time.perf_counter() - t
            snapshots.append(Snapshot(fraction=snap_steps[step + 1], iterations=step + 1, seconds=train_seconds + timings["init"] + timings["uncertainty"],
                                      renders=renders.astype(np.float32), depths=depths.astype(np.float32)))
    timings["train"] = train_seconds
    extra.update(n_gaussians=int(params["means"].shape[0]), n_clone=strategy.n_clone, n_split=strategy.n_split, n_prune=strategy.n_prune,
                 final_loss=float(np.mean(loss_hist[-20:])) if loss_hist else None)
    return Artifacts(snapshots=snapshots, timings=timings, iterations=iters, uncertainty=unc_full, extra=extra)


@torch.no_grad()
def _render_depths(params, views, viewmats, Ks, W, H, deg, bg, rkw, min_alpha: float = 0.5) -> np.ndarray:
    """(V, H, W) expected z-depth ``sum w z / sum w`` where alpha >= ``min_alpha``, else 0."""
    out = []
    for v in views:
        r = render(params, viewmats[int(v)], Ks[int(v)], W, H, deg, bg, **rkw)
        a = r["alpha"]
        out.append(torch.where(a >= min_alpha, r["depth"] / a.clamp_min(1e-6), torch.zeros_like(a)).numpy())
    return np.stack(out).astype(np.float32)


def _uncertainty_stage(scene, train, params, viewmats, Ks, W, H, deg, bg, rkw, cfg, seed):
    """Run the shared estimator on the training views; per-view depth weights and mask-constraint data."""
    from scipy.ndimage import distance_transform_edt

    from methods.monoinstance import run_uncertainty_stage  # the estimator shared with the SDF method

    ref_depth = _render_depths(params, train, viewmats, Ks, W, H, deg, bg, rkw)
    sub = restrict_scene(scene, train)
    res = run_uncertainty_stage(sub, ref_depth, cfg.uncertainty_config, rng_seed=seed)
    U = np.asarray(res.uncertainty, dtype=np.float32)
    inst = np.asarray(res.instance_ids, dtype=np.int32)
    u_cut = cfg.u_cut
    weights = {}
    for i, v in enumerate(train):
        c = 1.0 - U[i]
        c = np.where((inst[i] > 0) & (U[i] > u_cut), 0.0, c)
        weights[int(v)] = torch.tensor(c, dtype=torch.float32)
    mask_data = None
    if cfg.mask_constraint:
        thr = cfg.mask_u_threshold
        dist_maps = {}
        for i, v in enumerate(train):
            for k in np.unique(inst[i]):
                if k == 0:
                    continue
                m = inst[i] == k
                dist_maps[(int(v), int(k))] = torch.tensor(distance_transform_edt(~m), dtype=torch.float32)
        mask_data = {"U": {int(v): torch.tensor(U[i]) for i, v in enumerate(train)}, "inst": {int(v): torch.tensor(inst[i]) for i, v in enumerate(train)},
                     "dist": dist_maps, "thr": thr, "train": [int(v) for v in train], "max_pixels": cfg.mask_max_pixels}
    unc_full = np.zeros((scene.num_views, H, W), np.float32)
    unc_full[train] = U
    q = {k: (float(v) if isinstance(v, (int, float, np.floating)) else v) for k, v in (getattr(res, "quality", None) or {}).items()}
    q["timings"] = {k: float(v) for k, v in (getattr(res, "timings", None) or {}).items()}
    return weights, mask_data, unc_full, q


def _mask_loss(out, vi, md, viewmats, Ks, W, H) -> torch.Tensor:
    U, inst = md["U"][vi], md["inst"][vi]
    sel = torch.nonzero(((U > md["thr"]) & (inst > 0)).flatten()).squeeze(1)
    if sel.numel() == 0:
        return out["depth"].sum() * 0.0
    if sel.numel() > md["max_pixels"]:
        sel = sel[torch.randperm(sel.numel())[: md["max_pixels"]]]
    a = out["alpha"].flatten()[sel]
    d = out["depth"].flatten()[sel] / a.clamp_min(1e-3)
    vs = torch.div(sel, W, rounding_mode="floor").float()
    us = (sel % W).float()
    rays = torch.stack([us, vs, torch.ones_like(us)], -1) @ torch.linalg.inv(Ks[vi]).T
    c2w = torch.linalg.inv(viewmats[vi])
    pw = (rays * d[:, None]) @ c2w[:3, :3].T + c2w[:3, 3]
    views = [(j, Ks[j], viewmats[j]) for j in md["train"] if j != vi]
    loss, _ = losses.mask_constraint_loss(pw, inst.flatten()[sel], {(j, k): dm for (j, k), dm in md["dist"].items()}, views, W, H)
    return loss
