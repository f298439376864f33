"""The datasheet of a scene: every measured property in one JSON-able dict with stable keys.

Layout (``DATASHEET_VERSION`` 1; floats rounded to 4 significant digits, None where undefined):

    scene:        name, kind, format, views, height, width, prior_profile (None if not recorded)
    regions:      share of the valid GT pixels in each region (regions.py)
    depth_prior:  region -> abs_rel, delta1, n_views, n_pixels (priors.py), or None without a prior
    normal_prior: region -> mean_deg, median_deg, within_11_25, within_22_5, within_30, n_pixels, cdf
    photometric:  gradient energy / RMS per surface, textureless fraction (photometric.py)
    capture:      views, points_source, views_per_point, frac_single_view, ... (capture.py)
    thin_parts:   median_px, p90_px, n_axis_samples (thin.py)

Regions are ``all`` (every valid GT pixel), ``planar_background``, ``objects``, ``thin``, ``silhouette``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from bench.data.formats.codec import quantise_rgb
from bench.data.scene import Scene

from .capture import N_POINTS, SEED, capture_stats
from .photometric import photometric_stats
from .priors import depth_prior_stats, normal_prior_stats
from .regions import compute_regions
from .thin import thin_width_stats

DATASHEET_VERSION = 1
SIGNIFICANT_DIGITS = 4


def prior_profile(scene: Scene) -> str | None:
    """The simulated prior profile recorded in the scene's effects (``metadata["effects"]``), or None."""
    for record in scene.metadata.get("effects") or []:
        if isinstance(record, dict) and record.get("name") == "prior_profile":
            return str(record.get("profile"))
    return None


def compute_datasheet(scene: Scene, gt_mesh: Any | None = None, n_points: int = N_POINTS, seed: int = SEED) -> dict[str, Any]:
    """Measure ``scene`` (module docstring). ``gt_mesh``: its GT mesh (trimesh, world metres), else the
    capture statistics use back-projected GT depth. Deterministic.

    Raises:
        BenchInputError: the scene has no GT depth or GT instance ids.
    """
    regions = compute_regions(scene)
    parts = regions.partition()
    sheet: dict[str, Any] = {
        "version": DATASHEET_VERSION,
        "scene": {"name": scene.name, "kind": scene.kind, "format": scene.source_format, "views": scene.num_views,
                  "height": scene.height, "width": scene.width, "prior_profile": prior_profile(scene)},
        "regions": regions.fractions(),
        "depth_prior": None,
        "normal_prior": None,
        "photometric": photometric_stats(as_stored(scene.images), regions),
        "capture": capture_stats(scene, gt_mesh, n_points, seed),
        "thin_parts": thin_width_stats(regions.thin),
    }
    gt_depth = np.asarray(scene.gt_depth)
    if scene.mono_depth is not None:
        sheet["depth_prior"] = depth_prior_stats(np.asarray(scene.mono_depth), gt_depth, parts)
    if scene.mono_normal is not None and scene.gt_normal is not None:
        sheet["normal_prior"] = normal_prior_stats(np.asarray(scene.mono_normal), np.asarray(scene.gt_normal), parts)
    return rounded(sheet)


def as_stored(images: np.ndarray) -> np.ndarray:
    """The images as a dataset folder stores them and its loader returns them (8-bit, read back as float32 /
    255), so a synthesised scene and its written folder measure alike."""
    return quantise_rgb(images).astype(np.float32) / np.float32(255.0)


def rounded(obj: Any, digits: int = SIGNIFICANT_DIGITS) -> Any:
    """``obj`` with every float rounded to ``digits`` significant digits and NaN / inf made None."""
    if isinstance(obj, dict):
        return {k: rounded(v, digits) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [rounded(v, digits) for v in obj]
    if isinstance(obj, (float, np.floating)):
        x = float(obj)
        return float(f"{x:.{digits}g}") if math.isfinite(x) else None
    if isinstance(obj, np.integer):
        return int(obj)
    return obj

