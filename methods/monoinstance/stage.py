"""The MonoInstance uncertainty stage as one call, between stage 1 and stage 2 of a MonoInstance method.

``run_uncertainty_stage(scene, ref_depth, config)``:

1. align ``scene.mono_depth`` to ``ref_depth`` (:mod:`.alignment`);
2. associate ``scene.seg_masks`` across views with the aligned depth (:mod:`.association`);
3. density-based uncertainty per instance (:mod:`.uncertainty`);
4. if the scene has GT (``gt_depth``, ``gt_instance``), quality figures (:func:`stage_quality`).

It depends only on the :class:`bench.data.scene.Scene` and a reference depth (whatever rendered it: an SDF,
Gaussians, or GT in tests). Config: ``configs/methods/monoinstance_uncertainty.yaml`` (defaults);
``config`` overrides them; unknown keys are an error.
"""

from __future__ import annotations

import io
import time
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from bench.data.config import field_names
from methods.monoinstance.alignment import align_mono_depth_status
from methods.monoinstance.association import associate_instances
from methods.monoinstance.config import UncertaintyStageConfig, load_stage_config
from methods.monoinstance.quality import adjusted_rand_index, purity
from methods.monoinstance.uncertainty import InstanceUncertainty, estimate_uncertainty


def split_stage_config(config: Mapping[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """Split a method config into (this stage's keys, the rest)."""
    keys = set(field_names(UncertaintyStageConfig))
    return {k: v for k, v in config.items() if k in keys}, {k: v for k, v in config.items() if k not in keys}


@dataclass
class UncertaintyResult:
    """Output of :func:`run_uncertainty_stage`.

    Attributes:
        uncertainty: (N, H, W) float32 U in [0, 1] (0 = reliable prior; background / non-instance 0).
        instance_ids: (N, H, W) int32 multi-view consistent instance ids, 0 = none.
        is_background: instance id -> background flag.
        aligned_depth: (N, H, W) float32 mono depth aligned to the reference (metres), 0 = invalid.
        scale, shift: (N,) per-view alignment; align_status (N,) 0 fit / 1 scale-only / 2 fallback.
        timings: wall seconds ``align``, ``segmentation``, ``uncertainty`` (+ ``quality``, ``total``).
        quality: floats vs GT (empty without GT); see :func:`stage_quality`.
        diagnostics: association counts, failed instances, fallback views (floats).
        instances: per-instance :class:`InstanceUncertainty`.
        config: the resolved configuration.
    """

    uncertainty: np.ndarray
    instance_ids: np.ndarray
    is_background: dict[int, bool]
    aligned_depth: np.ndarray
    scale: np.ndarray
    shift: np.ndarray
    align_status: np.ndarray
    timings: dict[str, float] = field(default_factory=dict)
    quality: dict[str, float] = field(default_factory=dict)
    diagnostics: dict[str, float] = field(default_factory=dict)
    instances: dict[int, InstanceUncertainty] = field(default_factory=dict)
    config: UncertaintyStageConfig | None = None


def _nonfinite(name: str, arr: np.ndarray, policy: str) -> np.ndarray:
    bad = ~np.isfinite(arr)
    if not bad.any():
        return arr
    views = np.flatnonzero(bad.reshape(bad.shape[0], -1).any(1)).tolist()
    msg = f"{name} has NaN/inf in view(s) {views} ({int(bad.sum())} pixels)"
    if policy == "raise":
        raise ValueError(msg)
    warnings.warn(msg + ": masked as invalid", RuntimeWarning, stacklevel=3)
    return np.where(bad, 0.0, arr).astype(arr.dtype)


def run_uncertainty_stage(
    scene, ref_depth: np.ndarray, config: UncertaintyStageConfig | Mapping[str, Any] | None = None, rng_seed: int = 0,
    quality: bool = True,
) -> UncertaintyResult:
    """Alignment -> multi-view association -> density uncertainty (module docstring).

    Args:
        scene: :class:`bench.data.scene.Scene` with ``mono_depth``, ``seg_masks``, ``seg_background``.
        ref_depth: (N, H, W) reference z-depth in metres (stage-1 render; GT in tests), or
            (N, H/f, W/f) rendered at 1/f resolution. 0 = invalid.
        config: the stage's config, or overrides of ``configs/methods/monoinstance_uncertainty.yaml``.
        rng_seed: seeds the subsampling (same seed, same U).
        quality: compute :func:`stage_quality` when the scene has GT (about 1 s at small scale).

    Returns:
        :class:`UncertaintyResult`.

    Raises:
        ValueError: missing priors / segmentation, bad shapes, unknown config keys, or (with
            ``nonfinite_depth: raise``) NaN / inf in a depth map (the message names the views).
    """
    cfg = load_stage_config(config)
    if scene.mono_depth is None or scene.seg_masks is None or scene.seg_background is None:
        raise ValueError(f"scene {scene.name!r} needs mono_depth, seg_masks and seg_background for the uncertainty stage")
    n = scene.num_views
    ref = np.asarray(ref_depth, dtype=np.float32)
    if ref.ndim != 3 or ref.shape[0] != n:
        raise ValueError(f"ref_depth must be ({n}, H, W) or ({n}, H/f, W/f), got {ref.shape}")
    mono = _nonfinite("mono_depth", np.asarray(scene.mono_depth, dtype=np.float32), cfg.nonfinite_depth)
    ref = _nonfinite("ref_depth", ref, cfg.nonfinite_depth)
    radius = cfg.scene_radius if cfg.scene_radius is not None else scene.metres_per_unit
    cfg = cfg.with_scene_radius(radius)
    timings: dict[str, float] = {}
    t_all = t0 = time.perf_counter()
    aligned, scale, shift, status = align_mono_depth_status(
        mono, ref, cfg.align_mode, border_px=cfg.align_border_px, min_pixels=cfg.align_min_pixels
    )
    timings["align"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    assoc = associate_instances(
        scene.seg_masks, scene.seg_background, aligned, scene.intrinsics, scene.cam_to_world,
        cfg,
    )
    timings["segmentation"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    U, inst = estimate_uncertainty(
        aligned, assoc.global_ids, assoc.is_background, scene.intrinsics, scene.cam_to_world,
        cfg, np.random.default_rng(rng_seed),
    )
    timings["uncertainty"] = time.perf_counter() - t0
    timings["total"] = time.perf_counter() - t_all
    diag = assoc.diagnostics()
    fg = [r for r in inst.values() if r.status != "background"]
    diag.update(
        n_instances_fg=float(len(fg)),
        n_instances_bg=float(len(inst) - len(fg)),
        n_instances_failed=float(sum(r.status.startswith("failed") for r in fg)),
        n_align_fallback_views=float(np.sum(status == 2)),
        n_align_scale_only_views=float(np.sum(status == 1)),
        scene_radius_m=radius,
    )
    res = UncertaintyResult(
        uncertainty=U, instance_ids=assoc.global_ids, is_background=assoc.is_background, aligned_depth=aligned,
        scale=scale, shift=shift, align_status=status, timings=timings, diagnostics=diag, instances=inst, config=cfg,
    )
    if quality and scene.gt_depth is not None and scene.gt_instance is not None and scene.instances:
        t0 = time.perf_counter()
        res.quality = stage_quality(res, scene)
        timings["quality"] = time.perf_counter() - t0
    return res


def stage_quality(res: UncertaintyResult, scene) -> dict[str, float]:
    """Quality of a stage result against the scene's GT (all floats; NaN when undefined).

    Association (pixels with ``gt_instance > 0``; predicted id 0 is one label):
        ``assoc_ari``, ``assoc_purity`` over all GT pixels; ``assoc_ari_fg`` over GT foreground
        (non-background) pixels; ``seg_ari_per_view``: mean over views of the ARI of the raw per-view
        segmentation (the best any association could reach view by view); ``n_gt_instances``,
        ``n_pred_instances``.
    Uncertainty vs the prior's true error e = |aligned prior - GT depth| (metres), on "instance
    pixels" = predicted foreground instance pixels with GT and aligned depth valid:
        ``unc_ause``, ``unc_spearman`` (``metrics.uncertainty``), ``unc_ause_thin``, ``unc_spearman_thin``.
    Means of U per GT region (pixels with GT depth > 0, whatever the predicted segmentation):
        ``unc_mean_thin``: GT thin-structure pixels of foreground instances
        (``metrics.uncertainty.region_masks``, 5 x 5 opening: legs, poles, stems, silhouette spikes);
        ``unc_mean_planar``: the other (non-thin) pixels of foreground instances (table tops, seats,
        cabinet faces, sofa); ``unc_mean_background``: background instances (U = 0 by construction).
        ``err_mean_thin`` / ``err_mean_planar``: mean e on the same regions (the premise: the prior is
        worse on thin parts).
    """
    from metrics.uncertainty import region_masks, uncertainty_metrics

    gt_i = np.asarray(scene.gt_instance)
    gt_d = np.asarray(scene.gt_depth, dtype=np.float64)
    bg_ids = [i for i, v in scene.instances.items() if v.is_background]
    q: dict[str, float] = {}
    m = gt_i > 0
    fg_gt = m & ~np.isin(gt_i, bg_ids)
    pred = res.instance_ids
    q["assoc_ari"] = adjusted_rand_index(pred[m], gt_i[m])
    q["assoc_purity"] = purity(pred[m], gt_i[m])
    q["assoc_ari_fg"] = adjusted_rand_index(pred[fg_gt], gt_i[fg_gt])
    per_view = [adjusted_rand_index(scene.seg_masks[v][m[v]], gt_i[v][m[v]]) for v in range(gt_i.shape[0]) if m[v].sum() > 1]
    q["seg_ari_per_view"] = float(np.mean(per_view)) if per_view else float("nan")
    q["n_gt_instances"] = float(len(np.unique(gt_i[m])))
    q["n_pred_instances"] = float(len(np.unique(pred[pred > 0])))

    regions = region_masks(gt_i, bg_ids)
    thin = regions["thin"]
    planar_fg = fg_gt & ~thin
    fg_pred = (pred > 0) & ~np.isin(pred, [g for g, b in res.is_background.items() if b])
    valid = fg_pred & (res.aligned_depth > 0)
    um = uncertainty_metrics(res.uncertainty, res.aligned_depth, gt_d, valid=valid, regions={"thin": thin, "planar_fg": planar_fg})
    q["unc_ause"], q["unc_spearman"], q["unc_n_pixels"] = um["all"].ause, um["all"].spearman, float(um["all"].n_pixels)
    q["unc_ause_thin"], q["unc_spearman_thin"] = um["thin"].ause, um["thin"].spearman
    q["unc_ause_planar_fg"], q["unc_spearman_planar_fg"] = um["planar_fg"].ause, um["planar_fg"].spearman
    has_d = gt_d > 0
    err = np.abs(res.aligned_depth.astype(np.float64) - gt_d)
    err_ok = has_d & (res.aligned_depth > 0)
    for name, reg in (("thin", thin), ("planar", planar_fg), ("background", m & ~fg_gt)):
        sel = reg & has_d
        q[f"unc_mean_{name}"] = float(res.uncertainty[sel].mean()) if sel.any() else float("nan")
        q[f"n_px_{name}"] = float(sel.sum())
        se = reg & err_ok
        q[f"err_mean_{name}"] = float(err[se].mean()) if se.any() else float("nan")
    return q


def save_uncertainty_maps(result: UncertaintyResult, out_dir: str | Path, montage: bool = True) -> list[Path]:
    """Write ``uncertainty_{i:04d}.png`` (8-bit grey, round(255 U)) per view and, optionally,
    ``uncertainty_montage.png`` (views tiled, inferno colour map), each atomically (bench.data.atomic).

    Returns:
        the written paths.
    """
    from PIL import Image

    from bench.data.atomic import atomic_write_bytes

    out = Path(out_dir)
    U = np.clip(np.nan_to_num(np.asarray(result.uncertainty, dtype=np.float64)), 0.0, 1.0)
    u8 = np.round(U * 255.0).astype(np.uint8)

    def png(arr: np.ndarray) -> bytes:
        buf = io.BytesIO()
        Image.fromarray(arr).save(buf, format="PNG")
        return buf.getvalue()

    paths = []
    for i in range(u8.shape[0]):
        p = out / f"uncertainty_{i:04d}.png"
        atomic_write_bytes(p, png(u8[i]))
        paths.append(p)
    if montage and u8.shape[0]:
        from matplotlib import colormaps

        n, h, w = u8.shape
        cols = int(np.ceil(np.sqrt(n)))
        rows = int(np.ceil(n / cols))
        tile = np.zeros((rows * h, cols * w), dtype=np.float64)
        for i in range(n):
            r, c = divmod(i, cols)
            tile[r * h : (r + 1) * h, c * w : (c + 1) * w] = U[i]
        rgb = (colormaps["inferno"](tile)[..., :3] * 255.0).round().astype(np.uint8)
        p = out / "uncertainty_montage.png"
        atomic_write_bytes(p, png(rgb))
        paths.append(p)
    return paths
