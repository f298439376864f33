"""Depth metrics for monocular priors and rendered depth: AbsRel, RMSE, delta < 1.25.

Definitions over the valid pixels V of one image (``gt > 0``, finite, and the optional mask), after
an optional per-image alignment ``d' = s d + t`` fitted by least squares on V:

* AbsRel ``= mean_V |d' - g| / g``         (unitless, lower is better)
* RMSE   ``= sqrt(mean_V (d' - g)^2)``      (metres, lower is better)
* delta1 ``= mean_V [max(d'/g, g/d') < 1.25]`` (fraction, higher is better; d' <= 0 counts as a miss)

Alignment modes: ``"none"``, ``"scale"`` (``s = sum(d g) / sum(d^2)``, t = 0, as MonoInstance's
per-frame alignment) and ``"scale_shift"`` (MiDaS-style 2 x 2 least squares). Alignment is always
solved per image (never across images). A singular system (constant prior, or all-zero prior)
raises ValueError instead of silently returning s = t = 0 as MonoSDF's loss does.
Batches (N, H, W) give per-image values and their means.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from metrics._checks import to_numpy

AlignMode = Literal["none", "scale", "scale_shift"]


@dataclass(frozen=True)
class DepthMetrics:
    """Means over images of the per-image metrics, plus the per-image arrays (N,).

    Attributes:
        abs_rel, rmse (metres), delta1: means over images.
        per_image: dict name -> (N,) float64 for ``abs_rel``, ``rmse``, ``delta1``, ``scale``, ``shift``.
        n_valid: number of valid pixels per image (N,).
    """

    abs_rel: float
    rmse: float
    delta1: float
    per_image: dict[str, np.ndarray]
    n_valid: np.ndarray

    def as_dict(self) -> dict[str, float]:
        return {"abs_rel": self.abs_rel, "rmse": self.rmse, "delta1": self.delta1}


def align_depth(pred: Any, gt: Any, mask: Any | None = None, mode: AlignMode = "scale_shift") -> tuple[float, float]:
    """Least-squares scale (and shift) mapping ``pred`` onto ``gt`` over valid pixels of one image.

    Args:
        pred: (H, W) depth prior (any positive scale). gt: (H, W) z-depth, metres, 0 = invalid.
        mask: optional (H, W) bool; pixels used = mask & gt > 0 & finite.
        mode: ``"scale"`` or ``"scale_shift"`` (``"none"`` returns (1, 0)).

    Returns:
        (scale, shift) floats.

    Raises:
        ValueError: shapes differ, < 2 valid pixels, or singular system (constant / zero prior).
    """
    p, g, v = _prepare(pred, gt, mask, batched=False)
    return _align(p[0], g[0], v[0], mode)


def _prepare(pred: Any, gt: Any, mask: Any | None, batched: bool = True):
    p = np.asarray(to_numpy(pred, "pred"), dtype=np.float64)
    g = np.asarray(to_numpy(gt, "gt"), dtype=np.float64)
    if p.shape != g.shape:
        raise ValueError(f"pred shape {p.shape} and gt shape {g.shape} differ")
    if p.ndim == 2:
        p, g = p[None], g[None]
    if p.ndim != 3 or p.shape[0] == 0 or (not batched and p.shape[0] != 1):
        raise ValueError(f"depth maps must have shape (H, W){' or (N, H, W)' if batched else ''}, got {p.shape}")
    v = np.isfinite(g) & (g > 0) & np.isfinite(p)
    if mask is not None:
        m = to_numpy(mask, "mask")
        if m.dtype != np.bool_:
            raise TypeError(f"mask must be bool, got {m.dtype}")
        m = m[None] if m.ndim == 2 else m
        if m.shape != p.shape:
            raise ValueError(f"mask shape {m.shape} does not match depth shape {p.shape}")
        v &= m
    return p, g, v


def _align(p: np.ndarray, g: np.ndarray, v: np.ndarray, mode: str) -> tuple[float, float]:
    if mode == "none":
        return 1.0, 0.0
    x, y = p[v], g[v]
    if x.size < 2:
        raise ValueError(f"alignment needs >= 2 valid pixels, got {x.size}")
    if mode == "scale":
        den = float((x * x).sum())
        if den <= 0:
            raise ValueError("scale alignment is singular: the prior is zero on every valid pixel")
        return float((x * y).sum()) / den, 0.0
    if mode == "scale_shift":
        a00, a01, a11 = float((x * x).sum()), float(x.sum()), float(x.size)
        b0, b1 = float((x * y).sum()), float(y.sum())
        det = a00 * a11 - a01 * a01
        if det <= 1e-12 * max(a00 * a11, 1e-300):
            raise ValueError("scale/shift alignment is singular: the prior is constant on the valid pixels")
        return (a11 * b0 - a01 * b1) / det, (a00 * b1 - a01 * b0) / det
    raise ValueError(f"align must be 'none', 'scale' or 'scale_shift', got {mode!r}")


def depth_metrics(
    pred: Any,
    gt: Any,
    mask: Any | None = None,
    align: AlignMode = "none",
) -> DepthMetrics:
    """AbsRel, RMSE and delta < 1.25 of a depth map (prior or rendered) against GT z-depth.

    Args:
        pred: (H, W) or (N, H, W) predicted depth (metres, or arbitrary scale when aligned).
        gt: same shape, GT z-depth in metres, 0 = invalid (excluded).
        mask: optional bool, same shape: restrict the evaluation (and the alignment) to it.
        align: ``"none"``, ``"scale"`` or ``"scale_shift"``, solved per image.

    Returns:
        :class:`DepthMetrics`; an image without valid pixels raises ValueError.
    """
    p, g, v = _prepare(pred, gt, mask)
    if align not in ("none", "scale", "scale_shift"):
        raise ValueError(f"align must be 'none', 'scale' or 'scale_shift', got {align!r}")
    n = p.shape[0]
    out = {k: np.zeros(n) for k in ("abs_rel", "rmse", "delta1", "scale", "shift")}
    nv = v.reshape(n, -1).sum(1)
    if np.any(nv == 0):
        raise ValueError(f"images {np.flatnonzero(nv == 0).tolist()} have no valid pixel (gt > 0)")
    for i in range(n):
        s, t = _align(p[i], g[i], v[i], align)
        d = s * p[i][v[i]] + t
        y = g[i][v[i]]
        out["abs_rel"][i] = np.mean(np.abs(d - y) / y)
        out["rmse"][i] = np.sqrt(np.mean((d - y) ** 2))
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(d > 0, np.maximum(d / y, y / d), np.inf)
        out["delta1"][i] = np.mean(ratio < 1.25)
        out["scale"][i], out["shift"][i] = s, t
    return DepthMetrics(
        abs_rel=float(out["abs_rel"].mean()),
        rmse=float(out["rmse"].mean()),
        delta1=float(out["delta1"].mean()),
        per_image=out,
        n_valid=nv,
    )
