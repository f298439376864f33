"""Pixel widths of the thin parts (the ``thin`` region, :mod:`bench.data.datasheet.regions`).

Width along the medial axis: each view's thin mask is upsampled 2 x 2 by pixel replication (so every
integer width has a central line of half-pixels) and padded with one empty half-pixel (the image edge
bounds a part); its skeleton (``skimage.morphology.skeletonize``) is the medial axis, and the Euclidean
distance transform of the upsampled mask (``scipy.ndimage.distance_transform_edt``, distance from a
half-pixel to the nearest half-pixel outside the part) at an axis half-pixel, in half-pixels, is the
local width in pixels (2 x the half-width in pixels). This is exact for straight axis-aligned bars of
any integer width w (the axis distance is w half-pixels); diagonal and curved parts get the Euclidean
estimate, the ends of a part its narrowing tip. Statistics are over all axis half-pixels of all
views pooled (each part weighted by its length): median and 90th percentile, in pixels.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy import ndimage
from skimage.morphology import skeletonize


def axis_widths(thin: np.ndarray) -> np.ndarray:
    """Local widths (pixels) at the medial-axis samples of (N, H, W) or (H, W) bool masks, pooled."""
    masks = thin[None] if thin.ndim == 2 else thin
    widths = []
    for m in masks:
        if not m.any():
            continue
        up = np.pad(np.repeat(np.repeat(m, 2, axis=0), 2, axis=1), 1)
        widths.append(ndimage.distance_transform_edt(up)[skeletonize(up)])
    return np.concatenate(widths) if widths else np.zeros(0)


def thin_width_stats(thin: np.ndarray) -> dict[str, Any]:
    """``{"median_px", "p90_px", "n_axis_samples"}`` of :func:`axis_widths` (None values without thin pixels)."""
    w = axis_widths(thin)
    if w.size == 0:
        return {"median_px": None, "p90_px": None, "n_axis_samples": 0}
    return {"median_px": float(np.median(w)), "p90_px": float(np.percentile(w, 90)), "n_axis_samples": int(w.size)}
