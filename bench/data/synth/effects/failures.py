"""Failure regions: places where a monocular network's depth and normal predictions both go badly wrong.

Real priors have a heavy error tail that GT geometry alone does not explain: image content the
network misreads (mirrors, windows, screens, dark or blurred patches; none of which the synthesiser's
Lambertian renders contain) and errors of the real datasets' own GT, which the published figures
count too. This effect stands for that tail as random regions (optionally more often on foreground
objects, where clutter and the real GT's errors lie).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, cast

import numpy as np
from scipy.spatial.transform import Rotation

from bench.data.scene import Scene
from metrics.camera import pixel_rays

from ._params import param
from .depth import MIN_DEPTH
from .normals import orient_and_mask
from .registry import register

# assumed: a failure region ends within a couple of pixels (it follows an image segment: a mirror's or
# a screen's outline), so most of it is at full error, not a wide soft rim
EDGE_PX = 2.0


@dataclass(frozen=True)
class FailureRegionParams:
    count: float = param(
        1.0, "float", lo=0.0, hi=64.0, unit="1 / view", doc="mean number of regions per view (Poisson)"
    )
    radius_px: tuple[float, float] = param(
        (6.0, 16.0), "range", lo=0.0, lo_open=True, hi=512.0, unit="px", doc="region radius, drawn uniformly"
    )
    depth_error: tuple[float, float] = param(
        (0.2, 0.5),
        "range",
        lo=0.0,
        hi=0.9,
        unit="1 (relative)",
        doc="abs relative depth error at the region's core (sign random), drawn uniformly",
    )
    normal_error_deg: tuple[float, float] = param(
        (20.0, 60.0), "range", lo=0.0, hi=180.0, unit="deg", doc="normal rotation angle at the core, drawn uniformly"
    )
    follow_segment: bool = param(
        True,
        "bool",
        doc="a region covers only the GT instance its centre falls on (a misread image segment), not a plain disc",
    )
    background_weight: float = param(
        1.0,
        "float",
        lo=0.0,
        hi=1.0,
        unit="1",
        doc="relative chance of a region centre on a background-instance pixel vs a foreground one (1 = uniform)",
    )


def centre_weights(scene: Scene, v: int, valid: np.ndarray, background_weight: float) -> np.ndarray:
    """(H, W) probabilities of a region centre: valid pixels, those of background GT instances
    (``is_background``) weighted ``background_weight``, all others 1; uniform over valid pixels without
    ``gt_instance`` (or when nothing would remain)."""
    weights = valid.astype(np.float64)
    if scene.gt_instance is not None and background_weight < 1.0:
        inst = scene.gt_instance[v]
        background = [iid for iid, info in scene.instances.items() if info.is_background]
        weights = np.where(np.isin(inst, background), background_weight, 1.0) * valid
        if weights.sum() <= 0:
            weights = valid.astype(np.float64)
    total = weights.sum()
    return weights / total if total > 0 else weights


def region_weight(h: int, w: int, cx: float, cy: float, radius: float) -> np.ndarray:
    """(H, W) weight of one region: 1 up to ``EDGE_PX`` inside the radius (pixels, centre ``cx, cy`` in
    pixel units, pixel centres at +0.5), falling linearly to 0 at the radius."""
    yy, xx = np.mgrid[0:h, 0:w]
    dist = np.hypot(xx + 0.5 - cx, yy + 0.5 - cy)
    return np.clip((radius - dist) / EDGE_PX, 0.0, 1.0)


@register("prior_failure_regions", FailureRegionParams, needs=("mono_depth", "mono_normal", "intrinsics"))
def prior_failure_regions(scene: Scene, p: FailureRegionParams, rng: np.random.Generator) -> dict[str, Any]:
    """Random regions where both the depth and the normal prior fail grossly.

    Models: the heavy tail of real prior errors that scene geometry does not explain -- image content a
    network misreads (mirrors, windows, screens, dark or motion-blurred patches; absent from the
    synthesiser's Lambertian renders) and, in the published figures, the real datasets' own GT errors.
    Both heads of a network (or two networks trained on the same data) misread the same content, so
    one set of regions perturbs both priors (``depth_error`` 0: the normals only). Independent per view.

    Per view, ``n ~ Poisson(count)`` regions; each: centre at a valid pixel drawn with
    :func:`centre_weights` (uniform; or, with ``background_weight`` < 1, less often on background
    instances) plus a uniform offset within the pixel, radius ``~ U(radius_px)``, depth error
    ``e = +-U(depth_error)`` (sign 50/50), rotation axis uniform on the sphere, angle
    ``~ U(normal_error_deg)`` (drawn in this order). Weight ``w``: 1 up to ``EDGE_PX`` = 2 px inside the
    radius, falling linearly to 0 at the radius (:func:`region_weight`); with ``follow_segment`` (and
    ``gt_instance``) 0 outside the GT instance of the centre pixel, so a failure follows the outline of
    the segment it misreads (an object, a picture, a wall) instead of straddling a silhouette. ``d' = d (1 + e w)`` (floored
    at 1 mm); normals rotated by ``w`` x angle about the axis (scipy ``Rotation``), then unit length and
    facing the camera. Invalid pixels stay 0. Put it after the depth and normal effects it perturbs.

    Records per view the regions drawn, ``[cx, cy, radius_px, depth_error, axis_x, axis_y, axis_z,
    angle_deg]`` each, and the fraction of the image they cover.

    Parameters: count (mean per view), radius_px (px), depth_error (relative), normal_error_deg (deg),
    follow_segment (bool), background_weight (relative probability).
    """
    depth = cast(np.ndarray, scene.mono_depth)  # rendered by the synthesiser before any effect runs
    normals = cast(np.ndarray, scene.mono_normal)
    n_views, h, w = depth.shape
    drawn: list[list[list[float]]] = []
    area: list[float] = []
    for v in range(n_views):
        d = depth[v].astype(np.float64)
        n = normals[v].astype(np.float64)
        valid = d > 0
        k = int(rng.poisson(p.count)) if valid.any() else 0
        probs = centre_weights(scene, v, valid, p.background_weight).ravel()
        covered = np.zeros((h, w), dtype=bool)
        view_regions: list[list[float]] = []
        for _ in range(k):
            idx = int(rng.choice(probs.size, p=probs))
            cx, cy = idx % w + rng.uniform(), idx // w + rng.uniform()
            radius = rng.uniform(*p.radius_px)
            sign = 1.0 if rng.random() < 0.5 else -1.0
            err = sign * rng.uniform(*p.depth_error)
            axis = rng.standard_normal(3)
            axis /= max(float(np.linalg.norm(axis)), 1e-12)
            angle = np.radians(rng.uniform(*p.normal_error_deg))
            wt = region_weight(h, w, cx, cy, radius)
            if p.follow_segment and scene.gt_instance is not None:
                wt = wt * (scene.gt_instance[v] == scene.gt_instance[v][idx // w, idx % w])
            d = np.where(valid, np.maximum(d * (1.0 + err * wt), MIN_DEPTH), 0.0)
            rot = Rotation.from_rotvec((wt.reshape(-1, 1) * angle) * axis[None, :])
            n = rot.apply(n.reshape(-1, 3)).reshape(h, w, 3)
            covered |= wt > 0
            view_regions.append([float(cx), float(cy), float(radius), float(err), *map(float, axis), float(np.degrees(angle))])
        if covered.any():  # pixels outside every region keep their bytes
            K = np.asarray(scene.intrinsics[v], dtype=np.float64)
            has_normal = valid & (np.linalg.norm(normals[v], axis=-1) > 0.5)
            n = orient_and_mask(n, pixel_rays(K, h, w), has_normal)
            depth[v][covered] = d[covered].astype(np.float32)
            normals[v][covered] = n[covered].astype(np.float32)
        drawn.append(view_regions)
        area.append(float((covered & valid).mean()))
    return {"regions": drawn, "covered_frac": area}
