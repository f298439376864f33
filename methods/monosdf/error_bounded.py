"""VolSDF's error-bounded sampler (Yariv et al. 2021, Algorithm 1), as MonoSDF trains with it.

The alternative to :func:`methods.monosdf.render.hierarchical_samples` (``sampler: error_bounded`` in
``configs/methods/monosdf.yaml``). Everything here runs without gradients.

Per ray, starting from ``n_eval`` stratified samples in [near, far]:

1. the SDF at the samples bounds, per interval, how close the surface can come to the segment
   (:func:`interval_distance_bound`, VolSDF Theorem 1: ``d*``);
2. this bounds the error of the opacity estimated by the quadrature, for any beta
   (:func:`opacity_error_bound`, VolSDF Lemma 2 / Theorem 1);
3. a bisection finds the smallest beta+ >= beta (the model's) whose bound is <= ``eps``;
4. while beta+ > beta on some ray of the batch (and fewer than ``max_rounds`` rounds ran), ``n_eval``
   more samples are drawn from the pdf of the error bound and step 1 repeats on the union;
5. the final ``n_final`` samples are drawn from the VolSDF weights under beta+ (pdf + 1e-5), and joined
   by ``n_extra`` of the evaluated samples (the same random columns for every ray) plus near and far.

The final set (``n_final + n_extra + 2`` per ray, MonoSDF: 64 + 32 + 2) is what the renderer evaluates
with gradients. Units: distances along unit rays in normalised scene units; beta in the same units.
"""

from __future__ import annotations

import math
from typing import Literal, overload

import torch
from torch.profiler import record_function

from methods.monosdf.field import LaplaceDensity, SDFNetwork
from methods.monosdf.render import weights_and_transmittance

BOUND_CLAMP = 1e6  # VolSDF / MonoSDF: exp(error integral) is clamped here (no inf in the bound)
ERROR_PDF_FLOOR = 1e-6  # MonoSDF's add_tiny for the error-bound pdf of the upsampling rounds
WEIGHT_PDF_FLOOR = 1e-5  # MonoSDF's guard for the final weights pdf


def interval_distance_bound(t: torch.Tensor, sdf: torch.Tensor) -> torch.Tensor:
    """VolSDF's ``d*``: a lower bound on the distance from each interval to the surface.

    The SDF is a distance function, so no surface point lies inside the ball of radius |sdf_i| about
    sample i. For the segment between samples i and i+1 (length a, radii b = |sdf_i|, c = |sdf_i+1|),
    ``d*`` is the smallest distance from the segment to a point outside both balls: b or c when one
    ball's boundary is the nearest (an obtuse triangle), the triangle's height over the segment when
    the balls' boundaries meet above it, 0 when the balls leave a gap on the segment (b + c <= a) or the
    SDF changes sign across the interval (the surface crosses it).

    Args:
        t: (R, N) sorted distances along unit rays; sdf: (R, N) SDF at them.

    Returns:
        (R, N - 1) non-negative bounds, finite for finite inputs.
    """
    a = t[:, 1:] - t[:, :-1]
    b, c = sdf[:, :-1].abs(), sdf[:, 1:].abs()
    near_b = a * a + b * b <= c * c  # the ball about sample i+1 covers the foot of ball i: nearest point is b away
    near_c = a * a + c * c <= b * b
    s = 0.5 * (a + b + c)
    area = (s * (s - a) * (s - b) * (s - c)).clamp_min(0.0)  # Heron; rounding can make it slightly negative
    height = 2.0 * area.sqrt() / a.clamp_min(1e-12)
    d_star = torch.where(near_b, b, torch.where(near_c, c, torch.where(b + c - a > 0, height, torch.zeros_like(a))))
    same_sign = sdf[:, 1:].sign() * sdf[:, :-1].sign() == 1
    return torch.where(same_sign, d_star, torch.zeros_like(d_star))


def _error_integral(beta: torch.Tensor, d_star: torch.Tensor, dists: torch.Tensor) -> torch.Tensor:
    """(R, N-1) cumulative error of the free-energy quadrature up to each interval's end (VolSDF eq. 14)."""
    return torch.cumsum(torch.exp(-d_star / beta) * dists * dists / (4.0 * beta * beta), dim=-1)


def _bound_opacity(beta: torch.Tensor, d_star: torch.Tensor, dists: torch.Tensor, trans: torch.Tensor) -> torch.Tensor:
    """(R, N-1) bound on the opacity error at each interval's end: ``(exp(E_i) - 1) * T_i`` (exp clamped at
    1e6), T_i (R, N-1) the estimated transmittance at the interval's start."""
    return (torch.exp(_error_integral(beta, d_star, dists)).clamp(max=BOUND_CLAMP) - 1.0) * trans


def opacity_error_bound(beta: torch.Tensor, sdf: torch.Tensor, t: torch.Tensor, d_star: torch.Tensor,
                        density: LaplaceDensity) -> torch.Tensor:
    """The largest bound along each ray on the error of the estimated opacity, for density scale ``beta``.

    Args:
        beta: a scalar tensor or (R, 1) per ray; sdf, t: (R, N); d_star: (R, N - 1) from
            :func:`interval_distance_bound`.

    Returns:
        (R,) max over the ray of ``(exp(E_i) - 1) * T_i`` with E the error integral (exp clamped at 1e6)
        and T the estimated transmittance at the interval's start.
    """
    dists = t[:, 1:] - t[:, :-1]
    sigma = density(sdf, beta)
    free = torch.cumsum(torch.cat([torch.zeros_like(dists[:, :1]), dists * sigma[:, :-1]], dim=-1), dim=-1)
    return _bound_opacity(beta, d_star, dists, torch.exp(-free[:, :-1])).max(-1).values


def _invert_cdf(bins: torch.Tensor, pdf: torch.Tensor, n: int, gen: torch.Generator | None, random: bool) -> torch.Tensor:
    """(R, n) samples of the piecewise-constant ``pdf`` (R, B, normalised) over ``bins`` (R, B + 1)."""
    cdf = torch.cat([torch.zeros_like(pdf[:, :1]), torch.cumsum(pdf, -1)], -1)
    if random:
        u = torch.rand(bins.shape[0], n, generator=gen)
    else:  # MonoSDF: linspace(0, 1, n) for the upsampling rounds and evaluation
        u = torch.linspace(0.0, 1.0, n).expand(bins.shape[0], n)
    u = u.contiguous()
    above = torch.searchsorted(cdf, u, right=True).clamp(max=cdf.shape[1] - 1)
    below = (above - 1).clamp_min(0)
    c0, c1 = torch.gather(cdf, 1, below), torch.gather(cdf, 1, above)
    b0, b1 = torch.gather(bins, 1, below), torch.gather(bins, 1, above)
    denom = c1 - c0
    denom = torch.where(denom < 1e-5, torch.ones_like(denom), denom)
    return b0 + (u - c0) / denom * (b1 - b0)


@overload
def error_bounded_samples(
    sdf_net: SDFNetwork, density: LaplaceDensity, origins: torch.Tensor, dirs: torch.Tensor, far: torch.Tensor, near: float,
    n_eval: int, n_final: int, n_extra: int, eps: float, beta_iters: int, max_rounds: int, gen: torch.Generator | None,
    jitter: bool, with_coarse_sdf: Literal[False] = ...,
) -> torch.Tensor: ...
@overload
def error_bounded_samples(
    sdf_net: SDFNetwork, density: LaplaceDensity, origins: torch.Tensor, dirs: torch.Tensor, far: torch.Tensor, near: float,
    n_eval: int, n_final: int, n_extra: int, eps: float, beta_iters: int, max_rounds: int, gen: torch.Generator | None,
    jitter: bool, with_coarse_sdf: Literal[True],
) -> tuple[torch.Tensor, torch.Tensor]: ...
@overload
def error_bounded_samples(
    sdf_net: SDFNetwork, density: LaplaceDensity, origins: torch.Tensor, dirs: torch.Tensor, far: torch.Tensor, near: float,
    n_eval: int, n_final: int, n_extra: int, eps: float, beta_iters: int, max_rounds: int, gen: torch.Generator | None,
    jitter: bool, with_coarse_sdf: bool = ...,
) -> torch.Tensor | tuple[torch.Tensor, torch.Tensor]: ...
@torch.no_grad()
def error_bounded_samples(
    sdf_net: SDFNetwork, density: LaplaceDensity, origins: torch.Tensor, dirs: torch.Tensor, far: torch.Tensor, near: float,
    n_eval: int, n_final: int, n_extra: int, eps: float, beta_iters: int, max_rounds: int, gen: torch.Generator | None,
    jitter: bool, with_coarse_sdf: bool = False,
) -> torch.Tensor | tuple[torch.Tensor, torch.Tensor]:
    """The sampler of the module docstring.

    Args:
        origins: (R, 3); dirs: (R, 3) unit; far: (R,) distances; near: normalised units.
        n_eval: samples per evaluation round (MonoSDF: 128); n_final: samples from the final weights
            (64); n_extra: evaluated samples joined to them (32); eps: opacity error bound (0.1);
            beta_iters: bisection steps (10); max_rounds: evaluation rounds at most (5).
        jitter: training (stratified first round, random final draw, random extra columns) vs
            evaluation (deterministic).
        with_coarse_sdf: also return the (R, S) SDF already evaluated at the returned samples (the
            extra ones), NaN elsewhere (for ``render_rays(prune_weight=..., coarse_sdf=...)``).

    Returns:
        (R, S) sorted distances, S = n_final + min(n_extra, evaluated) + 2 [, (R, S) known SDF].
    """
    R = dirs.shape[0]
    near_t = torch.full((R,), float(near))
    far_t = torch.maximum(far, near_t + 1e-3)
    beta0 = density.beta().detach()
    u = (torch.arange(n_eval, dtype=torch.float32) + (torch.rand(R, n_eval, generator=gen) if jitter else 0.5)) / n_eval
    z = near_t[:, None] + (far_t - near_t)[:, None] * u  # (R, n_eval) stratified
    gaps = z[:, 1:] - z[:, :-1]
    beta = torch.sqrt((gaps * gaps).sum(-1) / (4.0 * math.log(1.0 + eps)))  # (R,) VolSDF Lemma 2: bound <= eps at this beta

    def sdf_at(tt: torch.Tensor) -> torch.Tensor:
        pts = origins[:, None, :] + dirs[:, None, :] * tt[..., None]
        with record_function("sampler.sdf"):
            return sdf_net(pts.reshape(-1, 3), with_gradient=False)[0].reshape(tt.shape)

    sdf = sdf_at(z)
    final = z
    for round_ in range(1, max_rounds + 1):
        d_star = interval_distance_bound(z, sdf)
        beta = torch.where(opacity_error_bound(beta0, sdf, z, d_star, density) <= eps, beta0.expand(R), beta)
        lo, hi = beta0.expand(R).clone(), beta.clone()
        for _ in range(beta_iters):
            mid = 0.5 * (lo + hi)
            ok = opacity_error_bound(mid[:, None], sdf, z, d_star, density) <= eps
            hi = torch.where(ok, mid, hi)
            lo = torch.where(ok, lo, mid)
        beta = hi
        weights, trans = weights_and_transmittance(sdf, z, density, beta[:, None])
        if bool(beta.max() > beta0) and round_ < max_rounds:  # upsample where the error bound is largest
            pdf = _bound_opacity(beta[:, None], d_star, z[:, 1:] - z[:, :-1], trans[:, :-1]) + ERROR_PDF_FLOOR
            new = _invert_cdf(z, pdf / pdf.sum(-1, keepdim=True), n_eval, gen, random=False)
            z, order = torch.sort(torch.cat([z, new], -1), -1)
            sdf = torch.gather(torch.cat([sdf, sdf_at(new)], -1), 1, order)
            continue
        pdf = weights[:, :-1] + WEIGHT_PDF_FLOOR
        final = _invert_cdf(z, pdf / pdf.sum(-1, keepdim=True), n_final, gen, random=jitter)
        break
    n_keep = min(int(n_extra), z.shape[1])
    if jitter:
        cols = torch.randperm(z.shape[1], generator=gen)[:n_keep]
    else:
        cols = torch.linspace(0, z.shape[1] - 1, n_keep).long()
    t, order = torch.sort(torch.cat([final, z[:, cols], near_t[:, None], far_t[:, None]], -1), -1)
    if not with_coarse_sdf:
        return t
    nan = torch.full((R, 1), float("nan"))
    known = torch.cat([torch.full_like(final, float("nan")), sdf[:, cols], nan, nan], -1)
    return t, torch.gather(known, 1, order)
