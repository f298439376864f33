"""Depth-prior effects: what monocular depth networks get wrong.

All depth effects act on ``scene.mono_depth`` (N, H, W) float32 z-depth, only where it is valid
(> 0): invalid pixels stay exactly 0 and the valid set never changes. Computation is float64, the
result is stored as float32.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Iterator, cast

import numpy as np
from scipy import ndimage

from bench.data.scene import Scene

from ._params import param
from .registry import register

MIN_DEPTH = 1e-3  # metres: floor keeping a valid prior positive after a negative shift


# ----------------------------------------------------------------------------- shared parameter fields
# Parameter fields shared by the depth and normal effects (one definition each; a dataclass field
# object cannot be shared between classes, hence factories).
def edge_threshold_field() -> Any:
    """``edge_threshold``: where an occlusion boundary is (:func:`depth_discontinuities`)."""
    return param(
        0.1,
        "float",
        lo=0.0,
        lo_open=True,
        unit="1",
        doc="occlusion boundary where abs(second difference of 1/z) > threshold * 1/z (0 on planes)",
    )


def edge_strength_field() -> Any:
    return param(1.0, "float", lo=0.0, hi=1.0, unit="1", doc="blend weight at the boundary")


def thin_kernel_field() -> Any:
    return param(5, "int", lo=0, hi=64, unit="px", doc="k of the k x k opening defining thin parts (< 2 = off)")


def max_freq_field() -> Any:
    return param(
        1.0,
        "float",
        lo=0.0,
        lo_open=True,
        hi=8.0,
        unit="cycles / image",
        doc="frequencies drawn in [0.5, 1] x max_freq cycles across the longer image side",
    )


def correlation_field(default: float) -> Any:
    return param(
        default, "float", lo=0.0, hi=64.0, unit="px", doc="Gaussian sigma correlating the noise field (0 = white)"
    )


# ----------------------------------------------------------------------------- mono_depth_affine
@dataclass(frozen=True)
class DepthAffineParams:
    scale: tuple[float, float] = param(
        (0.5, 2.0), "range", lo=0.0, lo_open=True, unit="1", doc="per-view scale s_v, drawn uniformly"
    )
    shift: tuple[float, float] = param(
        (0.0, 0.3), "range", unit="m (or x median depth)", doc="per-view shift t_v, drawn uniformly"
    )
    shift_mode: str = param(
        "absolute",
        "choice",
        choices=("absolute", "relative"),
        doc="'absolute': shift in metres; 'relative': shift times the view's median valid prior depth",
    )


@register("mono_depth_affine", DepthAffineParams, needs=("mono_depth",))
def mono_depth_affine(scene: Scene, p: DepthAffineParams, rng: np.random.Generator) -> dict[str, Any]:
    """Unknown per-view scale and shift of the depth prior (monocular depth is relative).

    Models: relative (affine-invariant) monocular depth networks, whose output matches metric
    z-depth only up to a scale and shift that differ from image to image.

    ``d' = s_v * d + t_v`` on valid pixels, with ``s_v ~ U(scale)``, ``t_v ~ U(shift)`` (metres) or,
    with ``shift_mode='relative'``, ``t_v ~ U(shift) * median(d[valid])``. Results below
    ``MIN_DEPTH`` = 1 mm are clamped to it so priors stay positive where valid (counted in
    ``sampled["clamped_px"]``; never happens for shift >= 0).

    Parameters: scale (range, unitless, > 0), shift (range, metres or fraction of median depth),
    shift_mode ('absolute' | 'relative').
    """
    depth = cast(np.ndarray, scene.mono_depth)  # rendered by the synthesiser before any effect runs
    scales, shifts, clamped = [], [], []
    for v in range(depth.shape[0]):
        d = depth[v].astype(np.float64)
        valid = d > 0
        s = float(rng.uniform(*p.scale))
        t = float(rng.uniform(*p.shift))
        if p.shift_mode == "relative":
            t *= float(np.median(d[valid])) if valid.any() else 0.0
        out = s * d + t
        low = valid & (out < MIN_DEPTH)
        out[low] = MIN_DEPTH
        depth[v] = np.where(valid, out, 0.0).astype(np.float32)
        scales.append(s)
        shifts.append(t)
        clamped.append(int(low.sum()))
    return {"scale": scales, "shift_m": shifts, "clamped_px": clamped}


# ----------------------------------------------------------------------------- depth_bleeding
@dataclass(frozen=True)
class DepthBleedingParams:
    edge_width_px: int = param(
        2, "int", lo=0, hi=64, unit="px", doc="half-width of the band blurred across occlusion boundaries (0 = off)"
    )
    edge_threshold: float = edge_threshold_field()
    edge_strength: float = edge_strength_field()
    thin_kernel_px: int = thin_kernel_field()
    thin_pull: tuple[float, float] = param(
        (0.2, 0.8), "range", lo=0.0, hi=1.0, unit="1", doc="fraction f pulling a thin part to the background depth"
    )
    thin_vanish_prob: float = param(
        0.1, "float", lo=0.0, hi=1.0, unit="1", doc="probability a thin part vanishes (f = 1) in a view"
    )


def thin_mask(mask: np.ndarray, k: int) -> np.ndarray:
    """Pixels of ``mask`` removed by a morphological opening with a k x k square: thin in image space.

    The mask is edge-padded first so that touching the image border does not count as thin.

    Args:
        mask: (H, W) bool. k: kernel size in pixels (< 2 gives an empty result).

    Returns:
        (H, W) bool.
    """
    if k < 2 or not mask.any():
        return np.zeros_like(mask, dtype=bool)
    padded = np.pad(mask, k, mode="edge")
    opened = ndimage.binary_opening(padded, structure=np.ones((k, k), dtype=bool))[k:-k, k:-k]
    return mask & ~opened


@dataclass(frozen=True)
class ThinPart:
    """The thin pixels of one foreground instance in one view (see :func:`thin_parts`).

    Attributes:
        instance_id: the GT instance id.
        mask: (H, W) bool, all thin pixels of the instance.
        components: its 8-connected components, (H, W) bool each, in label (raster) order.
        nearest_outside: index arrays (iy, ix), (H, W) each: for every pixel, the nearest valid pixel
            outside the instance (the background around it).
    """

    instance_id: int
    mask: np.ndarray
    components: list[np.ndarray]
    nearest_outside: tuple[np.ndarray, np.ndarray]


def thin_parts(scene: Scene, v: int, valid: np.ndarray, k: int) -> Iterator[ThinPart]:
    """The thin parts of view ``v``'s foreground GT instances, in increasing instance id.

    A foreground instance is one not marked ``is_background`` in ``scene.instances`` (or absent from
    it); its thin pixels are those a k x k opening removes (:func:`thin_mask`), restricted to
    ``valid``. Instances without thin pixels, or with no valid pixel outside them, are skipped.

    Args:
        scene: needs ``gt_instance``. v: view index. valid: (H, W) bool. k: opening size (< 2: none).
    """
    if k < 2 or scene.gt_instance is None:
        return
    inst = scene.gt_instance[v]
    for iid in np.unique(inst):
        iid = int(iid)
        if iid == 0:
            continue
        info = scene.instances.get(iid)
        if info is not None and info.is_background:
            continue
        mask = inst == iid
        thin = thin_mask(mask, k) & valid
        source = valid & ~mask
        if not thin.any() or not source.any():
            continue
        _, (iy, ix) = ndimage.distance_transform_edt(~source, return_indices=True)
        labels, n_comp = ndimage.label(thin, structure=np.ones((3, 3), dtype=bool))
        yield ThinPart(iid, thin, [labels == c for c in range(1, n_comp + 1)], (iy, ix))


def pull_thin_parts(
    values: np.ndarray,
    scene: Scene,
    v: int,
    valid: np.ndarray,
    k: int,
    pull: tuple[float, float],
    vanish_prob: float,
    rng: np.random.Generator,
) -> tuple[np.ndarray, list[float], int]:
    """Pull every thin component of view ``v`` (:func:`thin_parts`) towards the background around it.

    Per component, in instance then raster order: ``f ~ U(pull)``, then ``f = 1`` with ``vanish_prob``
    (two draws); ``out = (1 - f) values + f values[nearest pixel outside the instance]``.

    Args:
        values: (H, W) or (H, W, C) float64 field of the view (depth, normals).
        scene: needs ``gt_instance`` (nothing happens without it). valid: (H, W) bool. k: opening size.

    Returns:
        (pulled copy of ``values``, the fractions f drawn, number of thin pixels).
    """
    out = values.copy()
    fractions: list[float] = []
    n_thin = 0
    for part in thin_parts(scene, v, valid, k):
        background = values[part.nearest_outside]
        for comp in part.components:
            f = float(rng.uniform(*pull))
            if rng.random() < vanish_prob:
                f = 1.0
            out[comp] = (1.0 - f) * values[comp] + f * background[comp]
            fractions.append(f)
        n_thin += int(part.mask.sum())
    return out, fractions, n_thin


def depth_discontinuities(depth: np.ndarray, threshold: float) -> np.ndarray:
    """Occlusion-boundary pixels of a z-depth map (0 = invalid).

    Inverse depth is affine in pixel coordinates on a plane, so its second difference is 0 on planes
    (also at grazing angles) and large where the surface jumps. A pixel is marked when, along rows or
    columns, all three pixels are valid and ``|s[i-1] - 2 s[i] + s[i+1]| > threshold * s[i]``, s = 1/z.

    Returns:
        (H, W) bool.
    """
    valid = depth > 0
    s = np.where(valid, 1.0 / np.where(valid, depth, 1.0), 0.0)
    disc = np.zeros(depth.shape, dtype=bool)
    # along columns (u)
    dd = np.abs(s[:, :-2] - 2 * s[:, 1:-1] + s[:, 2:])
    ok = valid[:, :-2] & valid[:, 1:-1] & valid[:, 2:]
    disc[:, 1:-1] |= ok & (dd > threshold * s[:, 1:-1])
    # along rows (v)
    dd = np.abs(s[:-2] - 2 * s[1:-1] + s[2:])
    ok = valid[:-2] & valid[1:-1] & valid[2:]
    disc[1:-1] |= ok & (dd > threshold * s[1:-1])
    return disc


def blend_across_boundaries(
    values: np.ndarray, valid: np.ndarray, boundary: np.ndarray, width_px: int, strength: float
) -> tuple[np.ndarray, np.ndarray]:
    """Blend a field towards its local box average in a band around boundary pixels.

    Within ``width_px`` of a ``boundary`` pixel the value is moved towards its
    ``(2 width_px + 1)^2`` box average over valid pixels (so the two sides of the boundary mix), with
    a weight falling linearly from ``strength`` at the boundary to 0 at distance ``width_px``.

    Args:
        values: (H, W) or (H, W, C) float64 field (a vector field is averaged per component).
        valid: (H, W) bool, pixels that carry a value (the only ones averaged and changed).
        boundary: (H, W) bool boundary pixels (nothing happens when empty).
        width_px: half-width of the band in pixels (0 = off). strength: blend weight at the boundary.

    Returns:
        (blended copy of ``values``, (H, W) bool band of changed pixels).
    """
    out = values.copy()
    if width_px <= 0 or strength <= 0 or not boundary.any():
        return out, np.zeros(valid.shape, dtype=bool)
    dist = ndimage.distance_transform_edt(~boundary)
    weight = strength * np.clip(1.0 - dist / width_px, 0.0, 1.0)
    size = 2 * width_px + 1
    den = ndimage.uniform_filter(valid.astype(np.float64), size=size, mode="nearest")
    band = valid & (weight > 0)
    channels = [out] if out.ndim == 2 else [out[..., c] for c in range(out.shape[-1])]
    for ch in channels:  # views into ``out``: updated in place
        num = ndimage.uniform_filter(np.where(valid, ch, 0.0), size=size, mode="nearest")
        blur = np.where(den > 1e-9, num / np.maximum(den, 1e-9), ch)
        ch[band] = ch[band] + weight[band] * (blur[band] - ch[band])
    return out, band


@register("depth_bleeding", DepthBleedingParams, needs=("mono_depth",))
def depth_bleeding(scene: Scene, p: DepthBleedingParams, rng: np.random.Generator) -> dict[str, Any]:
    """Prior errors where monocular networks fail: occlusion boundaries and thin structures.

    Models: (a) the smooth, low-resolution decoders of monocular networks bleed depth between a
    foreground object and the background behind it; (b) thin structures (chair legs, poles, stems)
    are under-resolved and their depth is pulled towards the background around them, differently in
    every view, sometimes dropped entirely -- the multi-view inconsistency MonoInstance's density
    uncertainty detects (paper Sec. 1, 3.2, Fig. 3: chair legs).

    (b) Thin parts: for every foreground GT instance (``instances[id].is_background`` False, or not in
    the table) visible in a view, its thin pixels are those a ``thin_kernel_px`` x ``thin_kernel_px``
    opening removes. Each 8-connected thin component gets, independently per view,
    ``f ~ U(thin_pull)``, or ``f = 1`` with probability ``thin_vanish_prob`` (the part vanishes), and
    ``d' = (1 - f) d + f d_bg`` with ``d_bg`` the prior depth of the nearest valid pixel outside the
    instance (the surrounding background). Needs ``gt_instance``; skipped when absent.

    (a) Boundaries: occlusion boundaries are found on ``gt_depth`` (else on the prior) with
    :func:`depth_discontinuities`. Within ``edge_width_px`` of a boundary the prior is blended toward
    its (2w+1) x (2w+1) box average over valid pixels; the weight falls linearly from
    ``edge_strength`` at the boundary to 0 at distance w (pixels).

    Parameters: edge_width_px (px), edge_threshold (relative), edge_strength (0-1), thin_kernel_px
    (px), thin_pull (range of fractions in [0, 1]), thin_vanish_prob (probability).
    """
    depth = cast(np.ndarray, scene.mono_depth)  # rendered by the synthesiser before any effect runs
    n_views = depth.shape[0]
    pulls: list[list[float]] = []
    thin_px: list[int] = []
    edge_px: list[int] = []
    for v in range(n_views):
        d = depth[v].astype(np.float64)
        valid = d > 0
        # (b) thin structures, per foreground instance
        out, view_pulls, n_thin = pull_thin_parts(d, scene, v, valid, p.thin_kernel_px, p.thin_pull, p.thin_vanish_prob, rng)
        # (a) bleeding across occlusion boundaries
        n_edge = 0
        if p.edge_width_px > 0 and p.edge_strength > 0:
            ref = scene.gt_depth[v] if scene.gt_depth is not None else depth[v]
            disc = depth_discontinuities(ref.astype(np.float64), p.edge_threshold) & valid
            out, band = blend_across_boundaries(out, valid, disc, p.edge_width_px, p.edge_strength)
            n_edge = int(band.sum())
        depth[v] = np.where(valid, out, 0.0).astype(np.float32)
        pulls.append(view_pulls)
        thin_px.append(n_thin)
        edge_px.append(n_edge)
    return {"thin_pull": pulls, "thin_px": thin_px, "edge_px": edge_px}


# ----------------------------------------------------------------------------- lowfreq_warp
@dataclass(frozen=True)
class LowFreqWarpParams:
    amplitude: float = param(
        0.1, "float", lo=0.0, hi=0.9, unit="1", doc="max abs(w) of the multiplicative warp d' = d (1 + w)"
    )
    n_terms: int = param(3, "int", lo=1, hi=32, unit="1", doc="number of random 2D cosines summed")
    max_freq: float = max_freq_field()


def image_coords(h: int, w: int) -> tuple[np.ndarray, np.ndarray]:
    """(H, W) pixel-centre coordinates x, y divided by the longer image side (so in [0, 1])."""
    side = float(max(h, w))
    x, y = np.meshgrid((np.arange(w) + 0.5) / side, (np.arange(h) + 0.5) / side)
    return x, y


def lowfreq_field(rng: np.random.Generator, x: np.ndarray, y: np.ndarray, n_terms: int, max_freq: float) -> np.ndarray:
    """A random smooth field ``sum_k a_k cos(2 pi r_k (cos th_k x + sin th_k y) + phi_k)``.

    ``a_k ~ N(0, 1)``, ``r_k ~ U(0.5, 1) max_freq`` cycles per longer image side, ``th_k, phi_k ~
    U(0, 2 pi)``, drawn in that order per term. ``x``, ``y``: (H, W) from :func:`image_coords`.

    Returns:
        (H, W) float64 field, not normalised.
    """
    field = np.zeros(x.shape)
    for _ in range(n_terms):
        a = rng.standard_normal()
        r = rng.uniform(0.5, 1.0) * max_freq
        th = rng.uniform(0.0, 2 * np.pi)
        phi = rng.uniform(0.0, 2 * np.pi)
        field += a * np.cos(2 * np.pi * r * (np.cos(th) * x + np.sin(th) * y) + phi)
    return field


@register("lowfreq_warp", LowFreqWarpParams, needs=("mono_depth",))
def lowfreq_warp(scene: Scene, p: LowFreqWarpParams, rng: np.random.Generator) -> dict[str, Any]:
    """Smooth low-frequency multiplicative per-view warp: global bending of monocular depth.

    Models: monocular depth that is locally plausible but globally bent (planes curved, far parts
    compressed), differently in every image -- a shape error no per-view scale/shift removes.

    Per view ``w(x, y) = sum_k a_k cos(2 pi r_k (cos th_k x + sin th_k y) + phi_k)`` with x, y the pixel
    coordinates divided by the longer image side, ``a_k ~ N(0, 1)``, ``r_k ~ U(0.5, 1) max_freq``,
    ``th_k, phi_k ~ U(0, 2 pi)``; w is made zero-mean over the image (a mean is only a scale) and scaled
    to ``max |w| = amplitude``. ``d' = d (1 + w)`` on valid pixels.

    Parameters: amplitude (fraction, <= 0.9 so priors stay positive), n_terms (count), max_freq
    (cycles per longer image side).
    """
    depth = cast(np.ndarray, scene.mono_depth)  # rendered by the synthesiser before any effect runs
    n_views, h, w_px = depth.shape
    x, y = image_coords(h, w_px)
    peak = []
    for v in range(n_views):
        warp = lowfreq_field(rng, x, y, p.n_terms, p.max_freq)
        warp -= warp.mean()
        m = np.abs(warp).max()
        warp = warp * (p.amplitude / m) if m > 1e-12 else np.zeros_like(warp)
        d = depth[v].astype(np.float64)
        depth[v] = np.where(d > 0, d * (1.0 + warp), 0.0).astype(np.float32)
        peak.append(float(np.abs(warp).max()))
    return {"max_abs_warp": peak}


# ----------------------------------------------------------------------------- depth_noise
@dataclass(frozen=True)
class DepthNoiseParams:
    sigma: float = param(0.01, "float", lo=0.0, hi=0.5, unit="1 (relative)", doc="std of the multiplicative noise")
    correlation_px: float = correlation_field(0.0)


@register("depth_noise", DepthNoiseParams, needs=("mono_depth",))
def depth_noise(scene: Scene, p: DepthNoiseParams, rng: np.random.Generator) -> None:
    """Multiplicative Gaussian noise on the depth prior.

    Models: per-pixel jitter of network predictions (white), or, with ``correlation_px`` > 0, blotchy
    spatially correlated errors (e.g. a stochastic diffusion sampler). ``d' = d max(1 + sigma n, 0.1)``
    with n a unit-variance field: white N(0, 1), or N(0, 1) smoothed by a Gaussian of
    ``correlation_px`` pixels and renormalised to unit std. Independent per view.

    Parameters: sigma (relative std, <= 0.5), correlation_px (pixels).
    """
    depth = cast(np.ndarray, scene.mono_depth)  # rendered by the synthesiser before any effect runs
    for v in range(depth.shape[0]):
        n = rng.standard_normal(depth.shape[1:])
        if p.correlation_px > 0:
            n = ndimage.gaussian_filter(n, p.correlation_px, mode="reflect")
            std = n.std()
            n = n / std if std > 1e-12 else np.zeros_like(n)
        d = depth[v].astype(np.float64)
        depth[v] = np.where(d > 0, d * np.maximum(1.0 + p.sigma * n, 0.1), 0.0).astype(np.float32)
    return None
