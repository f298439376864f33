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
    near_t = torch.full((R,), float(near))
    far_t = torch.maximum(far, near_t + 1e-3)
    t_c = _stratified(near_t, far_t, n_coarse, gen, jitter)
    pts = origins[:, None, :] + dirs[:, None, :] * t_c[..., None]
    with record_function("sampler.sdf"):
        sdf_c, _, _ = sdf_net(pts.reshape(-1, 3), with_gradient=False)
    w_c = composite_weights(sdf_c.reshape(R, n_coarse), t_c, density)
    mids = 0.5 * (t_c[:, 1:] + t_c[:, :-1])
    bins = torch.cat([near_t[:, None], mids, far_t[:, None]], -1)
    t_f = sample_pdf(bins, w_c, n_fine, gen, jitter)
    t, order = torch.sort(torch.cat([t_c, t_f], -1), -1)
    if not with_coarse_sdf:
        return t
    known = torch.cat([sdf_c.reshape(R, n_coarse), torch.full((R, n_fine), float("nan"))], -1)
    return t, torch.gather(known, 1, order)


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
            training, when beta is small, most samples carry no weight (docs/monosdf.md, speed).
            ``RenderOutput.grad`` is 0 at pruned samples; ``RenderOutput.kept`` counts the rendered ones.
        coarse_sdf: (R, S) SDF already known at some samples (NaN elsewhere; ``hierarchical_samples(...,
            with_coarse_sdf=True)``): the pruning pass evaluates only the unknown ones.
    """
    R = dirs.shape[0]
    origins = origins.expand(R, 3)
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
    pts_g = flat if keep is None else flat[keep]
    n_g = pts_g.shape[0]
    with record_function("render.sdf_with_gradient"):
        sdf_g, geo, grad_g = sdf_net(pts_g if extra_points is None else torch.cat([pts_g, extra_points]), with_gradient=True)
    assert grad_g is not None
    extra_grad = None if extra_points is None else grad_g[n_g:]
    sdf_g, geo, grad_g = sdf_g[:n_g], geo[:n_g], grad_g[:n_g]  # the rendered samples (views without extra points)
    normals_g = F.normalize(grad_g, dim=-1, eps=1e-8)
    view = dirs[:, None, :].expand(R, S, 3).reshape(-1, 3)
    if isinstance(image, torch.Tensor):
        image = image[:, None].expand(R, S).reshape(-1)
        if keep is not None:
            image = image[keep]
    with record_function("render.color"):
        rgb_g = color_net(pts_g, view if keep is None else view[keep], normals_g, geo, image)
    if keep is None:
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
                        extra_grad=extra_grad, kept=n_g, kept_index=keep)
