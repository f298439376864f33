"""Quality of an uncertainty map U against the true error of the prior, e = |prior - GT|.

* Sparsification curve: remove the fraction f of pixels with the highest U and take the mean error of
  the rest, for f = 0, 1/B, ..., (B-1)/B (B = ``n_bins``, default 20). The oracle removes by true error.
* AUSE = area between the two curves (trapezoid over f in [0, (B-1)/B]), in the unit of the error
  (metres for depth); ``normalize=True`` divides both curves by the mean error first (unitless).
  AUSE >= 0; a perfect uncertainty (any strictly increasing function of e) gives 0.
* Ties in U are broken *in expectation*: when the cut falls inside a group of equal U, each member
  counts as removed in proportion, so the result does not depend on pixel order. All-equal U thus
  gives the random-removal curve (flat at the mean error) and AUSE = area between it and the oracle.
* Spearman rank correlation between U and e (``scipy.stats.spearmanr``, average ranks for ties).
  Undefined (NaN) when U or e is constant, e.g. all-equal uncertainty: documented, not an error.

Regions (:func:`region_masks`, from GT instance maps):

* ``thin``: pixels of a foreground (non-background) instance removed by a morphological opening of
  that instance's mask with a k x k square (default k = 5): parts narrower than k pixels in the image.
  The image is edge-padded before the opening so objects cut by the image border are not "thin".
* ``planar``: pixels of background instances (wall / floor / ceiling).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Iterable

import numpy as np

from metrics._checks import check_int, to_numpy


@dataclass(frozen=True)
class UncertaintyMetrics:
    """AUSE, Spearman rho and pixel count of one region (NaN values when < 2 pixels)."""

    ause: float
    spearman: float
    n_pixels: int

    def as_dict(self) -> dict[str, float]:
        return {"ause": self.ause, "spearman": self.spearman, "n_pixels": float(self.n_pixels)}


def _flat_pair(uncertainty: Any, error: Any) -> tuple[np.ndarray, np.ndarray]:
    u = np.asarray(to_numpy(uncertainty, "uncertainty"), dtype=np.float64).ravel()
    e = np.asarray(to_numpy(error, "error"), dtype=np.float64).ravel()
    if u.shape != e.shape:
        raise ValueError(f"uncertainty and error must have the same number of elements, got {u.size} and {e.size}")
    if u.size == 0:
        raise ValueError("uncertainty and error are empty")
    if not (np.all(np.isfinite(u)) and np.all(np.isfinite(e))):
        raise ValueError("uncertainty and error must be finite (select valid pixels first)")
    return u, e


def sparsification_curve(uncertainty: Any, error: Any, n_bins: int = 20) -> tuple[np.ndarray, np.ndarray]:
    """Mean remaining error after removing the most uncertain fractions (tie-aware).

    Args:
        uncertainty: (P,) or any shape, higher = less reliable.
        error: same number of elements, the true error (e.g. |prior - GT| in metres).
        n_bins: number of fractions B.

    Returns:
        fractions (B,) = i / B, curve (B,) mean error of the kept pixels.
    """
    u, e = _flat_pair(uncertainty, error)
    b = check_int(n_bins, "n_bins")
    n = u.size
    order = np.argsort(-u, kind="stable")
    us, es = u[order], e[order]
    csum = np.concatenate([[0.0], np.cumsum(es)])
    # group of equal U: start index of each position's group, and group sums / sizes
    new = np.concatenate([[True], us[1:] != us[:-1]])
    starts = np.flatnonzero(new)
    ends = np.concatenate([starts[1:], [n]])
    gmean = (csum[ends] - csum[starts]) / (ends - starts)
    fr = np.arange(b) / b
    k = np.floor(fr * n).astype(np.int64)  # number removed
    g = np.searchsorted(starts, k, side="right") - 1
    g = np.clip(g, 0, starts.size - 1)
    removed = csum[starts[g]] + (k - starts[g]) * gmean[g]
    curve = (csum[-1] - removed) / (n - k)
    return fr, curve


def ause(uncertainty: Any, error: Any, n_bins: int = 20, normalize: bool = False) -> float:
    """Area Under the Sparsification Error: area between U's curve and the oracle's.

    Args:
        uncertainty: (P,) (or any shape) uncertainty, higher = less reliable.
        error: same size, true error (>= 0), e.g. metres.
        n_bins: number of removal fractions (20).
        normalize: divide both curves by the mean error (unitless AUSE).

    Returns:
        AUSE >= 0 (error units, or unitless); 0 for a perfect uncertainty, and 0 when all errors are
        equal. With ``normalize`` and zero mean error, returns 0.
    """
    fr, cu = sparsification_curve(uncertainty, error, n_bins)
    _, co = sparsification_curve(error, error, n_bins)
    if normalize:
        m = float(np.mean(np.asarray(to_numpy(error, "error"), dtype=np.float64)))
        if m == 0:
            return 0.0
        cu, co = cu / m, co / m
    diff = cu - co
    if diff.size == 1:
        return 0.0
    return float(max(np.sum(0.5 * (diff[1:] + diff[:-1]) * np.diff(fr)), 0.0))


def spearman(uncertainty: Any, error: Any) -> float:
    """Spearman rank correlation between U and the error (NaN if either is constant)."""
    u, e = _flat_pair(uncertainty, error)
    if u.size < 2 or np.all(u == u[0]) or np.all(e == e[0]):
        return float("nan")
    from scipy.stats import spearmanr

    return float(spearmanr(u, e).statistic)


def region_masks(
    gt_instance: Any, background_ids: Iterable[int], kernel: int = 5
) -> dict[str, np.ndarray]:
    """Thin-structure and planar-background masks from GT instance maps.

    Args:
        gt_instance: (H, W) or (N, H, W) int GT instance ids, 0 = no surface.
        background_ids: ids of background instances (wall, floor, ceiling).
        kernel: side k of the square structuring element, pixels (odd, >= 3).

    Returns:
        ``{"thin": bool, "planar": bool}`` arrays of the input's shape.
    """
    from scipy import ndimage

    inst = to_numpy(gt_instance, "gt_instance")
    if not np.issubdtype(inst.dtype, np.integer):
        raise TypeError(f"gt_instance must be an integer array, got {inst.dtype}")
    if inst.ndim not in (2, 3):
        raise ValueError(f"gt_instance must have shape (H, W) or (N, H, W), got {inst.shape}")
    k = check_int(kernel, "kernel", 3)
    if k % 2 == 0:
        raise ValueError(f"kernel must be odd, got {k}")
    bg = np.asarray(sorted({int(i) for i in background_ids}), dtype=inst.dtype)
    batch = inst[None] if inst.ndim == 2 else inst
    planar = np.isin(batch, bg) & (batch > 0)
    thin = np.zeros(batch.shape, dtype=bool)
    r = k // 2
    st = np.ones((k, k), dtype=bool)
    for n in range(batch.shape[0]):
        padded = np.pad(batch[n], r, mode="edge")
        for i in np.unique(batch[n]):
            if i == 0 or i in bg:
                continue
            m = padded == i
            opened = ndimage.binary_opening(m, structure=st)
            thin[n] |= (m & ~opened)[r:-r, r:-r]
    if inst.ndim == 2:
        return {"thin": thin[0], "planar": planar[0]}
    return {"thin": thin, "planar": planar}


def uncertainty_metrics(
    uncertainty: Any,
    prior: Any,
    gt: Any,
    valid: Any | None = None,
    regions: dict[str, Any] | None = None,
    n_bins: int = 20,
    normalize: bool = False,
) -> dict[str, UncertaintyMetrics]:
    """AUSE and Spearman of U against e = |prior - gt|, overall and per region.

    Args:
        uncertainty: (H, W) or (N, H, W) U (higher = less reliable), e.g. U = 1 - c of MonoInstance.
        prior: same shape, the prior (e.g. aligned mono depth, metres).
        gt: same shape, GT (e.g. z-depth metres, 0 = invalid).
        valid: optional bool mask; pixels used = valid & gt > 0 & all finite.
        regions: optional ``{name: bool mask}`` (e.g. from :func:`region_masks`).
        n_bins, normalize: see :func:`ause`.

    Returns:
        ``{"all": ..., name: ...}`` of :class:`UncertaintyMetrics`; a region with < 2 valid pixels
        gets NaN metrics.
    """
    u = np.asarray(to_numpy(uncertainty, "uncertainty"), dtype=np.float64)
    p = np.asarray(to_numpy(prior, "prior"), dtype=np.float64)
    g = np.asarray(to_numpy(gt, "gt"), dtype=np.float64)
    if not (u.shape == p.shape == g.shape):
        raise ValueError(f"uncertainty {u.shape}, prior {p.shape} and gt {g.shape} must have the same shape")
    v = np.isfinite(u) & np.isfinite(p) & np.isfinite(g) & (g > 0)
    if valid is not None:
        m = to_numpy(valid, "valid")
        if m.shape != u.shape or m.dtype != np.bool_:
            raise ValueError(f"valid must be a bool array of shape {u.shape}, got {m.dtype} {m.shape}")
        v &= m
    masks = {"all": np.ones_like(v)}
    for name, m in (regions or {}).items():
        m = to_numpy(m, f"regions[{name!r}]")
        if m.shape != u.shape or m.dtype != np.bool_:
            raise ValueError(f"regions[{name!r}] must be a bool array of shape {u.shape}, got {m.dtype} {m.shape}")
        masks[name] = m
    err = np.abs(p - g)
    out = {}
    for name, m in masks.items():
        sel = v & m
        c = int(sel.sum())
        if c < 2:
            out[name] = UncertaintyMetrics(float("nan"), float("nan"), c)
            continue
        out[name] = UncertaintyMetrics(
            ause=ause(u[sel], err[sel], n_bins, normalize), spearman=spearman(u[sel], err[sel]), n_pixels=c
        )
    return out
