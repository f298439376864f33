"""Photometric content of the images: how much image gradient the surfaces carry.

* Luminance ``Y = 0.2126 R + 0.7152 G + 0.0722 B`` (Rec. 709 weights) of the stored 8-bit values / 255
  (gamma-encoded, as every method reads them), in [0, 1].
* **Gradient energy** of a pixel: ``e = gx^2 + gy^2`` with central differences
  ``gx = (Y[v, u+1] - Y[v, u-1]) / 2`` and ``gy = (Y[v+1, u] - Y[v-1, u]) / 2`` (units: (luminance / px)^2,
  no smoothing). A surface's gradient energy is the mean of e over its pixels, all views pooled,
  counting only pixels off the image border and outside the boundary band
  (:attr:`Regions.band`: 2 px either side of every instance boundary and depth discontinuity), so
  geometry edges and silhouettes do not count, only texture and shading inside a surface.
  For ``Y = c + a sin(2 pi u / P + phi)`` the energy is exactly ``a^2 sin^2(2 pi / P) / 2``.
  The card also shows ``255 sqrt(energy)``: the RMS gradient in 8-bit levels per pixel.
* **Textureless pixel**: its gradient magnitude, computed as above on the luminance smoothed by a
  Gaussian of ``TEXTURELESS_SIGMA_PX`` = 1 px (so the sensor noise does not count as texture), is
  below ``TEXTURELESS_THRESHOLD`` = 1/255 per pixel (one 8-bit level per pixel). Assumed values, no
  published definition: 1 px is the smallest smoothing that takes the default sensor noise (2 levels)
  down to about 0.3 levels/px; one level/px is the smallest contrast an 8-bit image stores across a few
  pixels. The smoothing reaches ~3 px, so within ~1 px outside the band a pixel can see its
  neighbouring surface. Reported: the fraction of wall and ceiling pixels (same pixels as above) that
  are textureless.

No published image-gradient statistics of ScanNet or Replica frames were found: there is no
real-data anchor for these numbers (the card says so).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy import ndimage

from .regions import SURFACE_CATEGORIES, Regions

LUMA_WEIGHTS = (0.2126, 0.7152, 0.0722)
TEXTURELESS_SIGMA_PX = 1.0
TEXTURELESS_THRESHOLD = 1.0 / 255.0


def luminance(images: np.ndarray) -> np.ndarray:
    """(N, H, W, 3) RGB in [0, 1] -> (N, H, W) float64 luminance."""
    return np.asarray(images, dtype=np.float64) @ np.asarray(LUMA_WEIGHTS)


def central_gradients(lum: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Central differences (gx, gy) of (N, H, W) maps, per pixel; 0 on the image border."""
    gx = np.zeros_like(lum)
    gy = np.zeros_like(lum)
    gx[:, :, 1:-1] = (lum[:, :, 2:] - lum[:, :, :-2]) / 2.0
    gy[:, 1:-1, :] = (lum[:, 2:, :] - lum[:, :-2, :]) / 2.0
    return gx, gy


def gradient_energy(lum: np.ndarray) -> np.ndarray:
    """(N, H, W) per-pixel gradient energy gx^2 + gy^2 of (N, H, W) luminance (0 on the border)."""
    gx, gy = central_gradients(lum)
    return gx * gx + gy * gy


def smoothed_gradient_magnitude(lum: np.ndarray, sigma_px: float = TEXTURELESS_SIGMA_PX) -> np.ndarray:
    """(N, H, W) gradient magnitude of each view's luminance after a Gaussian blur of ``sigma_px``."""
    blurred = np.stack([ndimage.gaussian_filter(view, sigma_px, mode="nearest") for view in lum])
    gx, gy = central_gradients(blurred)
    return np.sqrt(gx * gx + gy * gy)


def interior(shape: tuple[int, ...]) -> np.ndarray:
    """(N, H, W) bool: False on the one-pixel image border, where central differences are undefined."""
    m = np.zeros(shape, dtype=bool)
    m[:, 1:-1, 1:-1] = True
    return m


def photometric_stats(images: np.ndarray, regions: Regions) -> dict[str, Any]:
    """Gradient energy per surface and the textureless fraction of walls and ceiling (module docstring).

    Args:
        images: (N, H, W, 3) float RGB in [0, 1]. regions: the scene's :class:`Regions`.

    Returns:
        ``{"gradient_energy": {surface: float | None}, "gradient_rms_levels": {surface: float | None},
        "n_pixels": {surface: int}, "textureless_fraction_wall_ceiling": float | None,
        "textureless_threshold_levels": 1.0, "textureless_sigma_px": 1.0}`` for surfaces ``wall``,
        ``floor``, ``ceiling``, ``objects`` (None where a surface has no counted pixel).
    """
    lum = luminance(images)
    usable = interior(lum.shape) & regions.valid & ~regions.band
    masks = {cat: regions.surfaces[cat] & usable for cat in SURFACE_CATEGORIES}
    masks["objects"] = regions.objects & usable
    energy = gradient_energy(lum)
    stats: dict[str, Any] = {"gradient_energy": {}, "gradient_rms_levels": {}, "n_pixels": {}}
    for name, m in masks.items():
        n = int(m.sum())
        mean = float(energy[m].mean()) if n else None
        stats["gradient_energy"][name] = mean
        stats["gradient_rms_levels"][name] = 255.0 * float(np.sqrt(mean)) if mean is not None else None
        stats["n_pixels"][name] = n
    flat = masks["wall"] | masks["ceiling"]
    if flat.any():
        mag = smoothed_gradient_magnitude(lum)
        stats["textureless_fraction_wall_ceiling"] = float((mag[flat] < TEXTURELESS_THRESHOLD).mean())
    else:
        stats["textureless_fraction_wall_ceiling"] = None
    stats["textureless_threshold_levels"] = TEXTURELESS_THRESHOLD * 255.0
    stats["textureless_sigma_px"] = TEXTURELESS_SIGMA_PX
    return stats
