"""Normal-prior effects: normals of a simulated normal network (``normal_network``), normals derived
from the perturbed depth prior (``normal_from_depth``), and a per-view rigid rotation
(``normal_rotation``)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, cast

import numpy as np
from scipy import ndimage
from scipy.spatial.transform import Rotation

from bench.data.scene import Scene
from metrics.camera import pixel_rays

from ._params import param
from .depth import (
    blend_across_boundaries,
    correlation_field,
    depth_discontinuities,
    edge_strength_field,
    edge_threshold_field,
    image_coords,
    lowfreq_field,
    max_freq_field,
    pull_thin_parts,
    thin_kernel_field,
)
from .registry import register


def _one_sided_gradient(p: np.ndarray, valid: np.ndarray, z: np.ndarray, axis: int) -> tuple[np.ndarray, np.ndarray]:
    """Finite difference of points ``p`` (H, W, 3) along ``axis`` (1 = u, 0 = v).

    Uses the forward or backward difference whose two pixels are valid, preferring the one with the
    smaller depth change (so occlusion boundaries do not smear the normal). Returns (grad, ok).
    """
    fwd = np.zeros_like(p)
    bwd = np.zeros_like(p)
    dz_f = np.full(z.shape, np.inf)
    dz_b = np.full(z.shape, np.inf)
    if axis == 1:
        diff = p[:, 1:] - p[:, :-1]
        pair = valid[:, 1:] & valid[:, :-1]
        dz = np.abs(z[:, 1:] - z[:, :-1])
        fwd[:, :-1], bwd[:, 1:] = diff, diff
        dz_f[:, :-1] = np.where(pair, dz, np.inf)
        dz_b[:, 1:] = np.where(pair, dz, np.inf)
    else:
        diff = p[1:] - p[:-1]
        pair = valid[1:] & valid[:-1]
        dz = np.abs(z[1:] - z[:-1])
        fwd[:-1], bwd[1:] = diff, diff
        dz_f[:-1] = np.where(pair, dz, np.inf)
        dz_b[1:] = np.where(pair, dz, np.inf)
    use_f = dz_f <= dz_b
    grad = np.where(use_f[..., None], fwd, bwd)
    ok = np.isfinite(np.minimum(dz_f, dz_b))
    return grad, ok


def normals_from_depth(depth: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Camera-frame unit normals of a z-depth map by back-projection and finite differences.

    Points ``P = d * inv(K) [u, v, 1]`` (OpenCV axes); ``n = dP/du x dP/dv`` with one-sided
    differences (see :func:`_one_sided_gradient`), normalised and oriented towards the camera
    (``n . P < 0``). Pixels with no valid neighbour along u or v (isolated, 1-px structures) get the
    normal facing the camera, ``-P / |P|``.

    Args:
        depth: (H, W) z-depth in metres, 0 = invalid.
        K: (3, 3) intrinsics in pixels.

    Returns:
        (H, W, 3) float64 unit normals, 0 where depth is invalid.
    """
    h, w = depth.shape
    valid = depth > 0
    dirs = pixel_rays(K, h, w)
    pts = dirs * depth[..., None]
    gu, ok_u = _one_sided_gradient(pts, valid, depth, axis=1)
    gv, ok_v = _one_sided_gradient(pts, valid, depth, axis=0)
    n = np.cross(gu, gv)
    norm = np.linalg.norm(n, axis=-1)
    good = valid & ok_u & ok_v & (norm > 1e-12)
    facing = -dirs / np.linalg.norm(dirs, axis=-1, keepdims=True)
    n = np.where(good[..., None], n / np.where(good, norm, 1.0)[..., None], facing)
    return orient_and_mask(n, dirs, valid)


def orient_and_mask(n: np.ndarray, dirs: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Normalise, flip towards the camera, fall back to facing the camera if degenerate, zero invalid."""
    norm = np.linalg.norm(n, axis=-1, keepdims=True)
    facing = -dirs / np.linalg.norm(dirs, axis=-1, keepdims=True)
    n = np.where(norm > 1e-9, n / np.maximum(norm, 1e-12), facing)
    flip = np.sum(n * dirs, axis=-1) > 0
    n = np.where(flip[..., None], -n, n)
    return np.where(valid[..., None], n, 0.0)


def _align_scale_shift(pred: np.ndarray, target: np.ndarray, fit: str = "prior_to_gt") -> np.ndarray:
    """``pred`` mapped onto ``target`` by a per-view affine map over pixels valid in both; identity if
    degenerate or the scale is <= 0.

    ``fit``: ``"prior_to_gt"`` is least squares ``s pred + t ~ target`` (pred the regressor: its errors
    attenuate ``s``, compressing the depth range towards the view's mean); ``"gt_to_prior"`` is least
    squares ``pred ~ c target + d`` inverted, ``(pred - d) / c`` (target the regressor: no attenuation).
    """
    m = (pred > 0) & (target > 0)
    if m.sum() < 3:
        return pred
    if fit == "prior_to_gt":
        a = np.stack([pred[m], np.ones(int(m.sum()))], axis=1)
        (s, t), *_ = np.linalg.lstsq(a, target[m], rcond=None)
    elif fit == "gt_to_prior":
        a = np.stack([target[m], np.ones(int(m.sum()))], axis=1)
        (c, d), *_ = np.linalg.lstsq(a, pred[m], rcond=None)
        if not c > 0:  # the prior does not grow with GT depth: no alignment
            return pred
        s, t = 1.0 / c, -d / c
    else:
        raise ValueError(f"fit must be 'prior_to_gt' or 'gt_to_prior', got {fit!r}")
    if not (np.isfinite(s) and np.isfinite(t)) or s <= 0:
        return pred
    out = s * pred + t
    # keep the valid set and positivity of the prior
    return np.where(pred > 0, np.maximum(out, 1e-3), 0.0)


@dataclass(frozen=True)
class NormalFromDepthParams:
    blend_gt: float = param(
        0.0, "float", lo=0.0, hi=1.0, unit="1", doc="weight of the GT normal in the blend (0 = depth-derived only)"
    )
    smooth_px: float = param(
        0.0, "float", lo=0.0, hi=32.0, unit="px", doc="Gaussian sigma smoothing the normal field (0 = none)"
    )
    align_to_gt: bool = param(
        True,
        "bool",
        doc="fit the prior depth to GT depth by per-view scale/shift before differentiating, so the "
        "unknown shift does not shear the normals",
    )
    align_fit: str = param(
        "prior_to_gt",
        "choice",
        choices=("prior_to_gt", "gt_to_prior"),
        doc="the alignment's least squares: GT ~ s prior + t (the prior's errors attenuate s, so grazing "
        "surfaces face the camera more) or prior ~ c GT + d inverted (no attenuation; a diagnostic)",
    )


@register("normal_from_depth", NormalFromDepthParams, needs=("mono_depth", "intrinsics"))
def normal_from_depth(scene: Scene, p: NormalFromDepthParams, rng: np.random.Generator) -> None:
    """Normal priors recomputed from the (perturbed) depth prior, so depth errors show in normals.

    Models: monocular depth and normals come from the same foundation model and fail in the same
    regions (paper Sec. 4.1: "the monocular normals are homologous with depths"). Without this effect
    ``mono_normal`` keeps whatever it held (exact GT normals at synthesis).

    Per view: (optionally) align the depth prior to ``gt_depth`` by least-squares scale/shift --
    real normal networks do not inherit the depth's unknown shift, which would shear the normals --
    then :func:`normals_from_depth` with the view's K; blend ``(1 - blend_gt) n + blend_gt n_gt``
    where GT is valid; smooth each component with a Gaussian of ``smooth_px`` pixels over valid
    pixels; renormalise to unit length and orient towards the camera; 0 where the depth prior is
    invalid. Deterministic (draws nothing from ``rng``).

    Parameters: blend_gt (weight in [0, 1]), smooth_px (pixels), align_to_gt (bool), align_fit (which
    least-squares direction aligns the depth).
    """
    depth = cast(np.ndarray, scene.mono_depth)  # rendered by the synthesiser before any effect runs
    n_views, h, w = depth.shape
    if scene.mono_normal is None:
        scene.mono_normal = np.zeros((n_views, h, w, 3), dtype=np.float32)
    for v in range(n_views):
        d = depth[v].astype(np.float64)
        valid = d > 0
        if p.align_to_gt and scene.gt_depth is not None:
            d = _align_scale_shift(d, scene.gt_depth[v].astype(np.float64), p.align_fit)
        K = np.asarray(scene.intrinsics[v], dtype=np.float64)
        n = normals_from_depth(d, K)
        dirs = pixel_rays(K, h, w)
        if p.blend_gt > 0 and scene.gt_normal is not None:
            g = scene.gt_normal[v].astype(np.float64)
            has_gt = np.linalg.norm(g, axis=-1) > 0.5
            n = np.where(has_gt[..., None], (1.0 - p.blend_gt) * n + p.blend_gt * g, n)
            n = orient_and_mask(n, dirs, valid)
        if p.smooth_px > 0:
            wv = valid.astype(np.float64)
            den = ndimage.gaussian_filter(wv, p.smooth_px, mode="nearest")
            num = np.stack(
                [ndimage.gaussian_filter(n[..., c] * wv, p.smooth_px, mode="nearest") for c in range(3)], axis=-1
            )
            n = np.where(den[..., None] > 1e-9, num / np.maximum(den, 1e-9)[..., None], n)
            n = orient_and_mask(n, dirs, valid)
        scene.mono_normal[v] = n.astype(np.float32)
    return None


@dataclass(frozen=True)
class NormalRotationParams:
    max_deg: float = param(
        5.0, "float", lo=0.0, hi=90.0, unit="deg", doc="per-view rotation angle, drawn uniformly in [0, max_deg]"
    )


@register("normal_rotation", NormalRotationParams, needs=("mono_normal",))
def normal_rotation(scene: Scene, p: NormalRotationParams, rng: np.random.Generator) -> dict[str, list[Any]]:
    """Per-view rigid rotation of the normal prior: one rotation for all pixels of a view.

    Models: a normal network's per-image orientation bias, e.g. the gravity bias of networks trained on
    upright images, which rotates the prediction of a tilted camera as a whole (Do et al., ECCV 2020,
    "Surface normal estimation of tilted images via spatial rectifier"). Planes stay planar and the
    normals of one view stay mutually consistent; only the views disagree. A different error character
    from ``normal_from_depth`` after ``lowfreq_warp``, whose normals bend smoothly across each view.

    Per view: axis uniform on the unit sphere, angle ``~ U(0, max_deg)``; every valid (non-zero) camera-frame
    normal is rotated (scipy's ``Rotation.from_rotvec``), unit length kept, not re-oriented (a grazing normal may end up facing
    away, as a real network's can); invalid pixels stay 0.

    Parameters: max_deg (degrees).
    """
    normals = cast(np.ndarray, scene.mono_normal)
    angles, axes = [], []
    for v in range(normals.shape[0]):
        axis = rng.standard_normal(3)
        axis /= max(float(np.linalg.norm(axis)), 1e-12)
        theta = float(np.radians(rng.uniform(0.0, p.max_deg)))
        rot = Rotation.from_rotvec(theta * axis).as_matrix()
        n = normals[v].astype(np.float64)
        valid = np.linalg.norm(n, axis=-1) > 0.5
        normals[v] = np.where(valid[..., None], n @ rot.T, 0.0).astype(np.float32)
        angles.append(float(np.degrees(theta)))
        axes.append([float(a) for a in axis])
    return {"angle_deg": angles, "axis": axes}


# ----------------------------------------------------------------------------- normal_network
@dataclass(frozen=True)
class NormalNetworkParams:
    lowfreq_deg: float = param(
        3.0,
        "float",
        lo=0.0,
        hi=45.0,
        unit="deg",
        doc="RMS over the image of each component of the smooth per-view rotation-vector field",
    )
    lowfreq_spread: float = param(
        0.0,
        "float",
        lo=0.0,
        hi=1.0,
        unit="1",
        doc="per-view spread of that RMS: lowfreq_deg x U(1 - spread, 1 + spread) (images differ in difficulty)",
    )
    lowfreq_terms: int = param(3, "int", lo=1, hi=32, unit="1", doc="random 2D cosines summed per component")
    lowfreq_max_freq: float = max_freq_field()
    noise_deg: float = param(
        1.0, "float", lo=0.0, hi=45.0, unit="deg", doc="std of each component of the per-pixel rotation-vector noise"
    )
    noise_correlation_px: float = correlation_field(1.0)
    edge_width_px: int = param(
        2, "int", lo=0, hi=64, unit="px", doc="half-width of the band blended across occlusion boundaries (0 = off)"
    )
    edge_threshold: float = edge_threshold_field()
    edge_strength: float = edge_strength_field()
    crease_width_px: int = param(
        1, "int", lo=0, hi=64, unit="px", doc="half-width of the band blended across creases (0 = off)"
    )
    crease_deg: float = param(
        30.0,
        "float",
        lo=0.0,
        lo_open=True,
        hi=180.0,
        unit="deg",
        doc="crease where the GT normals of two 4-neighbours on the same surface differ by more than this",
    )
    detail_px: float = param(
        1.0,
        "float",
        lo=0.0,
        hi=32.0,
        unit="px",
        doc="Gaussian sigma smoothing normals within each foreground instance (small objects lose detail)",
    )
    thin_kernel_px: int = thin_kernel_field()
    thin_blend: tuple[float, float] = param(
        (0.2, 0.8),
        "range",
        lo=0.0,
        hi=1.0,
        unit="1",
        doc="fraction f blending a thin part's normals towards the background's",
    )
    thin_vanish_prob: float = param(
        0.1, "float", lo=0.0, hi=1.0, unit="1", doc="probability a thin part takes the background's normal (f = 1)"
    )


def normal_creases(normal: np.ndarray, valid: np.ndarray, min_deg: float, occlusion: np.ndarray) -> np.ndarray:
    """Pixels where the surface folds: a valid 4-neighbour's unit normal differs by more than ``min_deg``
    and neither pixel is an occlusion-boundary pixel (a silhouette is not a crease).

    Args:
        normal: (H, W, 3) unit normals. valid: (H, W) bool. min_deg: degrees. occlusion: (H, W) bool.

    Returns:
        (H, W) bool; both pixels of a folding pair are marked.
    """
    cos_min = np.cos(np.radians(min_deg))
    ok = valid & ~occlusion
    out = np.zeros(valid.shape, dtype=bool)
    for axis in (0, 1):
        a = [slice(None), slice(None)]
        b = [slice(None), slice(None)]
        a[axis], b[axis] = slice(None, -1), slice(1, None)
        ta, tb = tuple(a), tuple(b)
        fold = ok[ta] & ok[tb] & ((normal[ta] * normal[tb]).sum(-1) < cos_min)
        out[ta] |= fold
        out[tb] |= fold
    return out


def _smooth_within(n: np.ndarray, mask: np.ndarray, sigma: float) -> np.ndarray:
    """Normalised Gaussian smoothing of the vector field ``n`` (H, W, 3) over ``mask`` only; returns
    the smoothed vectors on ``mask`` (not renormalised) and ``n`` elsewhere."""
    w = mask.astype(np.float64)
    den = ndimage.gaussian_filter(w, sigma, mode="nearest")
    out = n.copy()
    inside = mask & (den > 1e-9)
    for c in range(3):
        num = ndimage.gaussian_filter(n[..., c] * w, sigma, mode="nearest")
        out[..., c][inside] = num[inside] / den[inside]
    return out


def _unit_field(rng: np.random.Generator, shape: tuple[int, int], correlation_px: float) -> np.ndarray:
    """(H, W) Gaussian noise of unit std: white, or smoothed by ``correlation_px`` and renormalised."""
    field = rng.standard_normal(shape)
    if correlation_px > 0:
        field = ndimage.gaussian_filter(field, correlation_px, mode="reflect")
        std = field.std()
        field = field / std if std > 1e-12 else np.zeros_like(field)
    return field


def _rotate(n: np.ndarray, rotvec: np.ndarray) -> np.ndarray:
    """Rotate each vector of ``n`` (H, W, 3) by its own rotation vector ``rotvec`` (H, W, 3), radians."""
    flat = Rotation.from_rotvec(rotvec.reshape(-1, 3)).apply(n.reshape(-1, 3))
    return flat.reshape(n.shape)


@register("normal_network", NormalNetworkParams, needs=("mono_depth", "gt_normal", "gt_depth", "intrinsics"))
def normal_network(scene: Scene, p: NormalNetworkParams, rng: np.random.Generator) -> dict[str, Any]:
    """A normal prior predicted by its own network: GT normals with the errors such networks make.

    Models: a monocular normal network (Omnidata's normal checkpoint, Metric3D v2's normal head,
    DSINE, GeoWizard's normal branch) run on each image separately. Its normals are accurate on large
    planes (a small, smooth, per-image error) and wrong where the image is ambiguous at its
    resolution: across silhouettes (the two sides' normals blended over a few pixels), on thin parts
    (their normals mixed with, or replaced by, the background's) and on small objects (detail smoothed
    away); plus a little per-pixel noise (Bae et al., ICCV 2021: errors concentrate near object
    boundaries and on small structures, large planes dominate training; docs/effects.md).

    Per view, starting from ``gt_normal``: (1) within each foreground GT instance the normals are
    smoothed by a normalised Gaussian of ``detail_px`` (restricted to the instance); (2) thin parts
    (``thin_kernel_px`` opening, as ``depth_bleeding``): each 8-connected component gets
    ``f ~ U(thin_blend)`` (``f = 1`` with ``thin_vanish_prob``) and ``n' = (1 - f) n + f n_bg``, ``n_bg``
    the normal of the nearest valid pixel outside the instance; (3) within ``edge_width_px`` of an
    occlusion boundary of ``gt_depth`` (:func:`depth_discontinuities`) and within ``crease_width_px``
    of a crease (:func:`normal_creases`) the normals are blended towards their box average, weight
    falling linearly from ``edge_strength`` (creases: 1) to 0; (4) every normal is rotated by a
    rotation vector, the sum of a smooth field (per component a sum of ``lowfreq_terms`` random 2D
    cosines, scaled to an RMS of ``lowfreq_deg`` x ``U(1 - lowfreq_spread, 1 + lowfreq_spread)``, one
    factor per view) and noise (per component ``noise_deg`` x unit-std
    Gaussian noise correlated over ``noise_correlation_px``); (5) unit length, oriented towards the
    camera, 0 where the depth prior is invalid. Every draw is independent per view (a network sees
    one image); nothing is derived from the depth prior. Skips (2) and the instance smoothing without
    ``gt_instance``.

    Parameters: lowfreq_deg, lowfreq_spread, lowfreq_terms, lowfreq_max_freq, noise_deg, noise_correlation_px,
    edge_width_px, edge_threshold, edge_strength, crease_width_px, crease_deg, detail_px,
    thin_kernel_px, thin_blend, thin_vanish_prob (units in docs/effects.md).
    """
    depth = cast(np.ndarray, scene.mono_depth)  # rendered by the synthesiser before any effect runs
    gt_normal = cast(np.ndarray, scene.gt_normal)
    gt_depth = cast(np.ndarray, scene.gt_depth)
    n_views, h, w = depth.shape
    if scene.mono_normal is None:
        scene.mono_normal = np.zeros((n_views, h, w, 3), dtype=np.float32)
    x, y = image_coords(h, w)
    blends: list[list[float]] = []
    thin_px: list[int] = []
    edge_px: list[int] = []
    crease_px: list[int] = []
    for v in range(n_views):
        valid = depth[v] > 0
        K = np.asarray(scene.intrinsics[v], dtype=np.float64)
        dirs = pixel_rays(K, h, w)
        g = gt_normal[v].astype(np.float64)
        has = valid & (np.linalg.norm(g, axis=-1) > 0.5)
        n = g.copy()
        # (1) small objects lose detail: smoothing within each foreground instance
        if p.detail_px > 0 and scene.gt_instance is not None:
            inst = scene.gt_instance[v]
            for iid in np.unique(inst[has]):
                info = scene.instances.get(int(iid))
                if info is not None and info.is_background:
                    continue
                n = _smooth_within(n, has & (inst == iid), p.detail_px)
        # (2) thin parts mixed with the background around them
        n, view_blends, n_thin = pull_thin_parts(n, scene, v, has, p.thin_kernel_px, p.thin_blend, p.thin_vanish_prob, rng)
        # (3) silhouettes and creases: the two sides blended
        occlusion = depth_discontinuities(gt_depth[v].astype(np.float64), p.edge_threshold) & has
        n, edge_band = blend_across_boundaries(n, has, occlusion, p.edge_width_px, p.edge_strength)
        creases = normal_creases(g, has, p.crease_deg, occlusion)
        n, crease_band = blend_across_boundaries(n, has, creases, p.crease_width_px, 1.0)
        # (4) smooth per-image rotation field + noise
        rotvec = np.zeros((h, w, 3))
        target_rms = np.radians(p.lowfreq_deg) * rng.uniform(1.0 - p.lowfreq_spread, 1.0 + p.lowfreq_spread)
        for c in range(3):
            field = lowfreq_field(rng, x, y, p.lowfreq_terms, p.lowfreq_max_freq)
            rms = float(np.sqrt(np.mean(field**2)))
            rotvec[..., c] = field * (target_rms / rms) if rms > 1e-12 else 0.0
        for c in range(3):
            rotvec[..., c] += np.radians(p.noise_deg) * _unit_field(rng, (h, w), p.noise_correlation_px)
        n = _rotate(n, rotvec)
        # (5) unit, facing the camera, 0 where the depth prior is invalid
        n = orient_and_mask(n, dirs, valid)
        scene.mono_normal[v] = n.astype(np.float32)
        blends.append(view_blends)
        thin_px.append(n_thin)
        edge_px.append(int(edge_band.sum()))
        crease_px.append(int(crease_band.sum()))
    return {"thin_blend": blends, "thin_px": thin_px, "edge_px": edge_px, "crease_px": crease_px}
