"""Error statistics of the monocular priors against GT, per region, by the published protocols.

Depth prior (the zero-shot protocol of affine-invariant depth, e.g. Marigold Table 1, GeoWizard
Table 1): each view's prior is aligned to the GT depth by a least-squares scale and shift
(:func:`metrics.depth.align_depth`, ``scale_shift``) fitted on all its pixels where both the GT and the
prior are valid (> 0); then, per region, AbsRel = mean |d' - g| / g and delta1 = fraction of pixels with
max(d'/g, g/d') < 1.25 (d' <= 0 counts as a miss) over the view's region pixels
(:func:`metrics.depth.depth_metrics`), and each statistic is the **mean over views** of the per-view
values (the published evaluations average per image). A region's mean is over the views that hold
at least one of its pixels; a view whose alignment is singular (< 2 valid pixels, constant prior) is
left out. AbsRel and delta1 are fractions in [0, 1].

Normal prior (the protocol of Omnidata / DSINE / Metric3D evaluations): the angle in degrees between
the prior and the GT normal (both normalised; a pixel counts where both are non-zero and the GT depth
is valid), **pooled over all pixels** of all views: mean, median, and the fractions within 11.25,
22.5 and 30 degrees; plus the cumulative distribution at ``CDF_STEP_DEG`` steps for the card's plot.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from metrics.depth import align_depth, depth_metrics

NORMAL_THRESHOLDS_DEG = (11.25, 22.5, 30.0)
CDF_STEP_DEG = 2.0
CDF_MAX_DEG = 90.0


def align_prior_depth(mono_depth: np.ndarray, gt_depth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-view least-squares scale + shift of the prior onto GT.

    Args:
        mono_depth: (N, H, W) prior depth (any scale), 0 = invalid. gt_depth: (N, H, W) metres, 0 = invalid.

    Returns:
        (aligned (N, H, W) float64 with ``s_v * prior + t_v`` where the prior is valid and 0 elsewhere,
        fitted (N,) bool: False for a view whose alignment is singular).
    """
    aligned = np.zeros(mono_depth.shape, dtype=np.float64)
    fitted = np.zeros(mono_depth.shape[0], dtype=bool)
    for v in range(mono_depth.shape[0]):
        prior = mono_depth[v].astype(np.float64)
        try:
            s, t = align_depth(prior, gt_depth[v], mask=prior > 0, mode="scale_shift")
        except ValueError:
            continue
        aligned[v] = np.where(prior > 0, s * prior + t, 0.0)
        fitted[v] = True
    return aligned, fitted


def depth_prior_stats(mono_depth: np.ndarray, gt_depth: np.ndarray, regions: dict[str, np.ndarray]) -> dict[str, dict[str, Any]]:
    """AbsRel / delta1 of the aligned prior per region (module docstring).

    Args:
        mono_depth, gt_depth: (N, H, W). regions: name -> (N, H, W) bool mask.

    Returns:
        name -> ``{"abs_rel", "delta1", "n_views", "n_pixels"}`` (the two statistics None when no view
        holds a pixel of the region).
    """
    aligned, fitted = align_prior_depth(mono_depth, gt_depth)
    usable = (mono_depth > 0) & (gt_depth > 0) & fitted[:, None, None]
    out: dict[str, dict[str, Any]] = {}
    for name, mask in regions.items():
        sel = mask & usable
        views = np.flatnonzero(sel.reshape(sel.shape[0], -1).any(1))
        if views.size == 0:
            out[name] = {"abs_rel": None, "delta1": None, "n_views": 0, "n_pixels": 0}
            continue
        m = depth_metrics(aligned[views], gt_depth[views], mask=sel[views], align="none")
        out[name] = {"abs_rel": m.abs_rel, "delta1": m.delta1, "n_views": int(views.size), "n_pixels": int(m.n_valid.sum())}
    return out


def angular_error_deg(pred: np.ndarray, gt: np.ndarray) -> np.ndarray:
    """Angle in degrees between two (..., 3) vector fields, each normalised first (zero vectors give NaN)."""
    p = np.asarray(pred, dtype=np.float64)
    g = np.asarray(gt, dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        p = p / np.linalg.norm(p, axis=-1, keepdims=True)
        g = g / np.linalg.norm(g, axis=-1, keepdims=True)
        cos = np.clip((p * g).sum(-1), -1.0, 1.0)
    return np.degrees(np.arccos(cos))


def normal_prior_stats(mono_normal: np.ndarray, gt_normal: np.ndarray, regions: dict[str, np.ndarray]) -> dict[str, dict[str, Any]]:
    """Angular-error statistics of the normal prior per region, pooled over pixels (module docstring).

    Args:
        mono_normal, gt_normal: (N, H, W, 3) camera-frame normals. regions: name -> (N, H, W) bool mask.

    Returns:
        name -> ``{"mean_deg", "median_deg", "within_11_25", "within_22_5", "within_30", "n_pixels",
        "cdf"}`` (fractions in [0, 1]; ``cdf[k]`` = fraction with error <= k * CDF_STEP_DEG degrees);
        None values for an empty region.
    """
    err = angular_error_deg(mono_normal, gt_normal)
    ok = np.isfinite(err)
    edges = np.arange(0.0, CDF_MAX_DEG + CDF_STEP_DEG / 2, CDF_STEP_DEG)
    out: dict[str, dict[str, Any]] = {}
    for name, mask in regions.items():
        e = np.sort(err[mask & ok])
        if e.size == 0:
            out[name] = {"mean_deg": None, "median_deg": None, **{within_key(t): None for t in NORMAL_THRESHOLDS_DEG},
                         "n_pixels": 0, "cdf": None}
            continue
        out[name] = {
            "mean_deg": float(e.mean()),
            "median_deg": float(np.median(e)),
            **{within_key(t): float((e < t).mean()) for t in NORMAL_THRESHOLDS_DEG},
            "n_pixels": int(e.size),
            "cdf": (np.searchsorted(e, edges, side="right") / e.size).tolist(),
        }
    return out


def within_key(threshold_deg: float) -> str:
    """``11.25`` -> ``"within_11_25"``, ``30.0`` -> ``"within_30"``."""
    text = f"{threshold_deg:g}".replace(".", "_")
    return f"within_{text}"
