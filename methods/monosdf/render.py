"""Volume rendering of an SDF (VolSDF / MonoSDF) with a hierarchical sampler.

Sampler (documented CPU-scale change, the default ``sampler: hierarchical``; MonoSDF uses VolSDF's
error-bounded sampler with 128 initial samples and up to 5 rounds, ``sampler: error_bounded``,
:mod:`methods.monosdf.error_bounded`): ``n_coarse`` stratified samples in [near, far] are evaluated
WITHOUT gradients, their VolSDF weights (current beta) define a piecewise-constant pdf (+1e-5, as
MonoSDF's guard), ``n_fine`` samples are drawn from it by inverse CDF, and the sorted union
(``n_coarse + n_fine`` samples per ray) is evaluated with gradients and composited.

Outputs per ray: colour, z-depth (normalised units: distance-weighted mean times the z factor, divided
by the accumulated weight + 1e-8, MonoSDF's formula), camera-frame normal, accumulated weight, and
the SDF gradients used by the eikonal term.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, overload

import torch
import torch.nn.functional as F
from torch.profiler import record_function

from methods.monosdf.field import ColorNetwork, LaplaceDensity, SDFNetwork


@dataclass
class RenderOutput:
    """Rendered quantities for R rays (S samples each).

    Attributes:
        rgb: (R, 3); depth: (R,) z-depth in normalised units; normal: (R, 3) camera frame (not
        normalised); acc: (R,) sum of weights; weights: (R, S); grad: (R, S, 3) SDF gradients at the
        samples; sdf: (R, S); t: (R, S) sample distances; extra_grad: (E, 3) SDF gradients at the
        ``extra_points`` (None without); kept: samples rendered with gradients (R * S unless pruned);
        kept_index: their flat indices into R * S (None = every sample).
    """

    rgb: torch.Tensor
    depth: torch.Tensor
    normal: torch.Tensor
    acc: torch.Tensor
    weights: torch.Tensor
    grad: torch.Tensor
    sdf: torch.Tensor
    t: torch.Tensor
    extra_grad: torch.Tensor | None = None
    kept: int = 0
    kept_index: torch.Tensor | None = None  # (K,) flat indices (into R * S) of the samples rendered with gradients; None = all

    def select(self, rows: slice | torch.Tensor) -> "RenderOutput":
        """The same outputs for a subset of the rays (``extra_grad`` is dropped: it is not per ray)."""
        return RenderOutput(rgb=self.rgb[rows], depth=self.depth[rows], normal=self.normal[rows], acc=self.acc[rows],
                            weights=self.weights[rows], grad=self.grad[rows], sdf=self.sdf[rows], t=self.t[rows])


def weights_and_transmittance(sdf: torch.Tensor, t: torch.Tensor, density: LaplaceDensity,
                              beta: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
    """VolSDF weights ``w_i = T_i (1 - exp(-sigma_i delta_i))`` and transmittances ``T_i`` along rays.

    Args:
        sdf: (R, S) SDF at the samples; t: (R, S) sorted distances along unit rays; beta: None (the
            density's own), a scalar tensor or (R, 1) per ray.

    Returns:
        (R, S) weights (the last interval extends 1e10, i.e. the ray is absorbed) and (R, S) T_i.
    """
    sigma = density(sdf, beta)
    delta = torch.cat([t[:, 1:] - t[:, :-1], torch.full_like(t[:, :1], 1e10)], dim=1)
    free = sigma * delta
    trans = torch.exp(-torch.cumsum(torch.cat([torch.zeros_like(free[:, :1]), free[:, :-1]], dim=1), dim=1))
    return trans * (1.0 - torch.exp(-free)), trans


def composite_weights(sdf: torch.Tensor, t: torch.Tensor, density: LaplaceDensity, beta: torch.Tensor | None = None) -> torch.Tensor:
    """The (R, S) weights of :func:`weights_and_transmittance`."""
    return weights_and_transmittance(sdf, t, density, beta)[0]


def _stratified(near: torch.Tensor, far: torch.Tensor, n: int, gen: torch.Generator | None, jitter: bool) -> torch.Tensor:
    u = torch.linspace(0.0, 1.0, n + 1)[:-1]
    u = u.expand(near.shape[0], n)
    if jitter:
        u = u + torch.rand(u.shape, generator=gen) / n
    else:
        u = u + 0.5 / n
    return near[:, None] + (far - near)[:, None] * u


def sample_pdf(bins: torch.Tensor, weights: torch.Tensor, n: int, gen: torch.Generator | None, jitter: bool) -> torch.Tensor:
    """Inverse-CDF sampling of a piecewise-constant pdf.

    Args:
        bins: (R, B+1) bin edges; weights: (R, B) non-negative; n: samples per ray.

    Returns:
        (R, n) samples, sorted.
    """
    pdf = weights + 1e-5
    pdf = pdf / pdf.sum(-1, keepdim=True)
    cdf = torch.cat([torch.zeros_like(pdf[:, :1]), torch.cumsum(pdf, -1)], -1)
    if jitter:
        u = (torch.arange(n, dtype=bins.dtype) + torch.rand(bins.shape[0], n, generator=gen)) / n
    else:
        u = ((torch.arange(n, dtype=bins.dtype) + 0.5) / n).expand(bins.shape[0], n)
    u = u.contiguous().clamp(0.0, 1.0 - 1e-6)
    idx = torch.searchsorted(cdf, u, right=True).clamp(1, cdf.shape[1] - 1)
    c0, c1 = torch.gather(cdf, 1, idx - 1), torch.gather(cdf, 1, idx)
    b0, b1 = torch.gather(bins, 1, idx - 1), torch.gather(bins, 1, idx)
    frac = (u - c0) / (c1 - c0).clamp_min(1e-8)
    return b0 + frac * (b1 - b0)


def _coarse_distances(dirs: torch.Tensor, far: torch.Tensor, near: float, n_coarse: int, gen: torch.Generator | None,
                      jitter: bool) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The sampler's first half: ``(near_t (R,), far_t (R,), t_coarse (R, n_coarse))``, stratified in [near, far]."""
    R = dirs.shape[0]
    near_t = torch.full((R,), float(near))
    far_t = torch.maximum(far, near_t + 1e-3)
    return near_t, far_t, _stratified(near_t, far_t, n_coarse, gen, jitter)


@torch.no_grad()
def _fine_distances(sdf_coarse: torch.Tensor, t_coarse: torch.Tensor, near_t: torch.Tensor, far_t: torch.Tensor,
                    density: LaplaceDensity, n_fine: int, gen: torch.Generator | None, jitter: bool) -> torch.Tensor:
    """The sampler's second half: (R, n_fine) importance samples (unsorted) from the VolSDF weights of the
    (R, n_coarse) coarse SDF, with the coarse intervals' midpoints as bin edges."""
    w_c = composite_weights(sdf_coarse, t_coarse, density)
    mids = 0.5 * (t_coarse[:, 1:] + t_coarse[:, :-1])
    bins = torch.cat([near_t[:, None], mids, far_t[:, None]], -1)
    return sample_pdf(bins, w_c, n_fine, gen, jitter)


@overload
def hierarchical_samples(
    sdf_net: SDFNetwork, density: LaplaceDensity, origins: torch.Tensor, dirs: torch.Tensor, far: torch.Tensor,
    near: float, n_coarse: int, n_fine: int, gen: torch.Generator | None, jitter: bool, with_coarse_sdf: Literal[False] = ...,
) -> torch.Tensor: ...
@overload
def hierarchical_samples(
    sdf_net: SDFNetwork, density: LaplaceDensity, origins: torch.Tensor, dirs: torch.Tensor, far: torch.Tensor,
    near: float, n_coarse: int, n_fine: int, gen: torch.Generator | None, jitter: bool, with_coarse_sdf: Literal[True],
) -> tuple[torch.Tensor, torch.Tensor]: ...
@overload
def hierarchical_samples(
    sdf_net: SDFNetwork, density: LaplaceDensity, origins: torch.Tensor, dirs: torch.Tensor, far: torch.Tensor,
    near: float, n_coarse: int, n_fine: int, gen: torch.Generator | None, jitter: bool, with_coarse_sdf: bool = ...,
) -> torch.Tensor | tuple[torch.Tensor, torch.Tensor]: ...
@torch.no_grad()
def hierarchical_samples(
    sdf_net: SDFNetwork, density: LaplaceDensity, origins: torch.Tensor, dirs: torch.Tensor, far: torch.Tensor,
    near: float, n_coarse: int, n_fine: int, gen: torch.Generator | None, jitter: bool, with_coarse_sdf: bool = False,
) -> torch.Tensor | tuple[torch.Tensor, torch.Tensor]:
    """The sampler of the module docstring -> (R, n_coarse + n_fine) sorted distances (no gradient);
    ``with_coarse_sdf``: also the (R, n_coarse + n_fine) SDF the coarse pass computed, NaN at the fine
    samples (``render_rays(prune_weight=...)`` then evaluates only those)."""
    R = dirs.shape[0]
    near_t, far_t, t_c = _coarse_distances(dirs, far, near, n_coarse, gen, jitter)
    pts = origins[:, None, :] + dirs[:, None, :] * t_c[..., None]
    with record_function("sampler.sdf"):
        sdf_c, _, _ = sdf_net(pts.reshape(-1, 3), with_gradient=False)
    t_f = _fine_distances(sdf_c.reshape(R, n_coarse), t_c, near_t, far_t, density, n_fine, gen, jitter)
    t, order = torch.sort(torch.cat([t_c, t_f], -1), -1)
    if not with_coarse_sdf:
        return t
    known = torch.cat([sdf_c.reshape(R, n_coarse), torch.full((R, n_fine), float("nan"))], -1)
    return t, torch.gather(known, 1, order)


@dataclass
class CoarseGradientPass:
    """The hierarchical sampler's coarse samples evaluated WITH gradients (``coarse_gradient_pass``, config):
    the fine samples are drawn from their detached SDF, and :func:`render_rays` renders them from these
    outputs instead of evaluating the coarse samples a second time (one no-gradient SDF pass fewer per step;
    the same samples, values and gradients as the two-pass sampler up to float rounding).

    Attributes:
        t: (R, S) sorted distances, S = n_coarse + n_fine (what :func:`hierarchical_samples` returns);
        order: (R, S) int64, ``t = cat([t_coarse, t_fine], 1).gather(1, order)``;
        t_coarse: (R, n_coarse) the coarse (stratified) distances; t_fine: (R, n_fine) the fine distances in the
        order they were drawn;
        sdf: (R * n_coarse,), geo: (R * n_coarse, G), grad: (R * n_coarse, 3): the SDF network at the coarse
        samples (ray-major), with their autograd graph.
    """

    t: torch.Tensor
    order: torch.Tensor
    t_coarse: torch.Tensor
    t_fine: torch.Tensor
    sdf: torch.Tensor
    geo: torch.Tensor
    grad: torch.Tensor

    def block_points(self, origins: torch.Tensor, dirs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The (R * n_coarse, 3) coarse and (R * n_fine, 3) fine sample points (ray-major, drawn order) of rays
        ``origins`` (R, 3), ``dirs`` (R, 3)."""
        return tuple((origins[:, None, :] + dirs[:, None, :] * tt[..., None]).reshape(-1, 3)  # type: ignore[return-value]
                     for tt in (self.t_coarse, self.t_fine))

    def ray_of_block(self) -> torch.Tensor:
        """(R * S,) the ray of each sample of the block layout ``[coarse (ray-major), fine (ray-major)]``."""
        R = self.t.shape[0]
        rays = torch.arange(R)
        return torch.cat([rays.repeat_interleave(self.t_coarse.shape[1]), rays.repeat_interleave(self.t_fine.shape[1])])

    def sorted_index(self) -> torch.Tensor:
        """(R * S,) for each sample of the sorted (R, S) layout (flattened), its index in the block layout."""
        R, S = self.order.shape
        n_c, n_f = self.t_coarse.shape[1], self.t_fine.shape[1]
        rows = torch.arange(R)[:, None]
        return torch.where(self.order < n_c, rows * n_c + self.order, R * n_c + rows * n_f + (self.order - n_c)).reshape(-1)


def hierarchical_samples_with_gradient(
    sdf_net: SDFNetwork, density: LaplaceDensity, origins: torch.Tensor, dirs: torch.Tensor, far: torch.Tensor,
    near: float, n_coarse: int, n_fine: int, gen: torch.Generator | None, jitter: bool,
) -> CoarseGradientPass:
    """:func:`hierarchical_samples` whose coarse SDF pass keeps its gradients (same random draws, same
    distances): for :func:`render_rays` ``(coarse=...)``. ``origins``: (R, 3); ``dirs``: (R, 3) unit; ``far``: (R,)."""
    R = dirs.shape[0]
    near_t, far_t, t_c = _coarse_distances(dirs, far, near, n_coarse, gen, jitter)
    pts = origins[:, None, :] + dirs[:, None, :] * t_c[..., None]
    with record_function("sampler.sdf_with_gradient"):
        sdf_c, geo_c, grad_c = sdf_net(pts.reshape(-1, 3), with_gradient=True)
    assert grad_c is not None  # asked for (with_gradient=True)
    t_f = _fine_distances(sdf_c.detach().reshape(R, n_coarse), t_c, near_t, far_t, density, n_fine, gen, jitter)
    with torch.no_grad():
        t, order = torch.sort(torch.cat([t_c, t_f], -1), -1)
    return CoarseGradientPass(t=t, order=order, t_coarse=t_c, t_fine=t_f, sdf=sdf_c, geo=geo_c, grad=grad_c)


@torch.no_grad()
def render_depth(
    sdf_net: SDFNetwork, density: LaplaceDensity, origins: torch.Tensor, dirs: torch.Tensor, z_factor: torch.Tensor,
    far: torch.Tensor, near: float, n_coarse: int, n_fine: int, t: torch.Tensor | None = None,
) -> torch.Tensor:
    """z-depth only (no colour, no normals, no gradients): (R,) normalised units. Used to render the
    reference depth between MonoInstance's stages. ``t``: (R, S) sample distances from another sampler
    (None = the hierarchical one with ``n_coarse`` + ``n_fine``, deterministic)."""
    R = dirs.shape[0]
    origins = origins.expand(R, 3)
    if t is None:
        t = hierarchical_samples(sdf_net, density, origins, dirs, far, near, n_coarse, n_fine, None, False)
    sdf, _, _ = sdf_net((origins[:, None, :] + dirs[:, None, :] * t[..., None]).reshape(-1, 3), with_gradient=False)
    w = composite_weights(sdf.reshape(R, -1), t, density)
    return (w * t).sum(-1) / (w.sum(-1) + 1e-8) * z_factor


def render_rays(
    sdf_net: SDFNetwork,
    color_net: ColorNetwork,
    density: LaplaceDensity,
    origins: torch.Tensor,
    dirs: torch.Tensor,
    z_factor: torch.Tensor,
    far: torch.Tensor,
    world_to_cam: torch.Tensor,
    near: float,
    n_coarse: int,
    n_fine: int,
    gen: torch.Generator | None = None,
    jitter: bool = True,
    extra_points: torch.Tensor | None = None,
    t: torch.Tensor | None = None,
    image: int | torch.Tensor | None = None,
    prune_weight: float = 0.0,
    coarse_sdf: torch.Tensor | None = None,
    coarse: CoarseGradientPass | None = None,
) -> RenderOutput:
    """Render R rays.

    Args:
        origins: (R, 3) or (3,); dirs: (R, 3) unit; z_factor, far: (R,); world_to_cam: (3, 3) or (R, 3, 3).
        near: near distance (normalised units). n_coarse, n_fine: samples (see module docstring).
        gen: random generator for stratification (None = global). jitter: stratified jitter (training).
        extra_points: (E, 3) points whose SDF gradients are wanted too (the eikonal term's uniform
            points): evaluated in the same SDF pass as the samples (one grid call and one table-sized
            gradient buffer instead of two), returned in ``RenderOutput.extra_grad``.
        t: (R, S) sample distances from :func:`hierarchical_samples` when the caller drew them already
            (e.g. to place eikonal points beside them); None = draw them here.
        image: training slot of the rays, an int or (R,) per ray (selects the colour network's per-image
            code; None = the mean code).
        prune_weight: > 0 renders with gradients only the samples whose weight, from a no-gradient pass
            over all samples, exceeds it (plus each ray's highest-weight sample); the others keep their
            no-gradient SDF in the compositing (so transmittance is unchanged) and no colour / normal
            (their weights are below ``prune_weight``). 0 = every sample with gradients (MonoSDF). Late in
            training, when beta is small, most samples carry no weight (docs/studies/monosdf-speed.md).
            ``RenderOutput.grad`` is 0 at pruned samples; ``RenderOutput.kept`` counts the rendered ones.
        coarse_sdf: (R, S) SDF already known at some samples (NaN elsewhere; ``hierarchical_samples(...,
            with_coarse_sdf=True)``): the pruning pass evaluates only the unknown ones.
        coarse: the coarse samples already evaluated with gradients (:func:`hierarchical_samples_with_gradient`,
            whose distances are used; ``t`` must be None): only the fine samples and ``extra_points`` are
            evaluated here, every sample is rendered (no ``prune_weight``). The slow twin is the two-pass
            sampler (``coarse=None``): the same outputs and gradients up to float rounding.
    """
    R = dirs.shape[0]
    origins = origins.expand(R, 3)
    if coarse is not None:
        if t is not None or prune_weight > 0:
            raise ValueError("render_rays: coarse= brings its own distances and renders every sample (no t=, no prune_weight)")
        t = coarse.t
    if t is None:
        t = hierarchical_samples(sdf_net, density, origins, dirs, far, near, n_coarse, n_fine, gen, jitter)
    S = t.shape[1]
    pts = origins[:, None, :] + dirs[:, None, :] * t[..., None]
    flat = pts.reshape(-1, 3)
    keep = None
    if prune_weight > 0:
        with torch.no_grad(), record_function("render.prune_pass"):
            if coarse_sdf is None:
                sdf_all = sdf_net(flat, with_gradient=False)[0]
            else:
                sdf_all = coarse_sdf.reshape(-1).clone()
                todo = sdf_all.isnan().nonzero().squeeze(1)
                sdf_all[todo] = sdf_net(flat[todo], with_gradient=False)[0]
            w_all = composite_weights(sdf_all.reshape(R, S), t, density)
            mask = w_all > prune_weight
            mask[torch.arange(R), w_all.argmax(-1)] = True
            keep = mask.reshape(-1).nonzero().squeeze(1)  # (K,) flat sample indices rendered with gradients
    if coarse is None:  # the points rendered with gradients: the sorted (R * S) layout, or its kept subset
        pts_g = flat if keep is None else flat[keep]
        evaluated = pts_g
    else:  # the block layout [coarse samples, fine samples] (ray-major each); the coarse ones are evaluated already
        pts_c, evaluated = coarse.block_points(origins, dirs)
        pts_g = torch.cat([pts_c, evaluated])
    n_g = evaluated.shape[0]
    with record_function("render.sdf_with_gradient"):
        sdf_g, geo, grad_g = sdf_net(evaluated if extra_points is None else torch.cat([evaluated, extra_points]), with_gradient=True)
    assert grad_g is not None
    extra_grad = None if extra_points is None else grad_g[n_g:]
    sdf_g, geo, grad_g = sdf_g[:n_g], geo[:n_g], grad_g[:n_g]  # the rendered samples (views without extra points)
    if coarse is not None:
        sdf_g, geo, grad_g = torch.cat([coarse.sdf, sdf_g]), torch.cat([coarse.geo, geo]), torch.cat([coarse.grad, grad_g])
    normals_g = F.normalize(grad_g, dim=-1, eps=1e-8)
    if coarse is not None:
        ray_of = coarse.ray_of_block()
    else:
        ray_of = torch.arange(R).repeat_interleave(S)
        if keep is not None:
            ray_of = ray_of[keep]
    view = dirs.index_select(0, ray_of)
    if isinstance(image, torch.Tensor):
        image = image.index_select(0, ray_of)
    with record_function("render.color"):
        rgb_g = color_net(pts_g, view, normals_g, geo, image)
    if coarse is not None:  # gather the block layout into the sorted (R * S) one
        index = coarse.sorted_index()
        sdf, grad, normals, rgb_s = (v.index_select(0, index) for v in (sdf_g, grad_g, normals_g, rgb_g))
    elif keep is None:
        sdf, grad, normals, rgb_s = sdf_g, grad_g, normals_g, rgb_g
    else:  # scatter the rendered samples into the full (R * S) layout; pruned ones: no-gradient SDF, 0 elsewhere
        sdf = sdf_all.index_put((keep,), sdf_g)
        grad = torch.zeros(R * S, 3).index_put((keep,), grad_g)
        normals = torch.zeros(R * S, 3).index_put((keep,), normals_g)
        rgb_s = torch.zeros(R * S, 3).index_put((keep,), rgb_g)
    rgb_s = rgb_s.reshape(R, S, 3)
    sdf = sdf.reshape(R, S)
    w = composite_weights(sdf, t, density)
    acc = w.sum(-1)
    rgb = (w[..., None] * rgb_s).sum(1)
    depth = (w * t).sum(-1) / (acc + 1e-8) * z_factor
    n_world = (w[..., None] * normals.reshape(R, S, 3)).sum(1)
    if world_to_cam.dim() == 2:
        n_cam = n_world @ world_to_cam.T
    else:
        n_cam = torch.einsum("rij,rj->ri", world_to_cam, n_world)
    return RenderOutput(rgb=rgb, depth=depth, normal=n_cam, acc=acc, weights=w, grad=grad.reshape(R, S, 3), sdf=sdf, t=t,
                        extra_grad=extra_grad, kept=pts_g.shape[0], kept_index=keep)
