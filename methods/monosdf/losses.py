"""MonoSDF's losses, with optional per-ray weights (MonoInstance's adaptive prior loss uses them).

All take tensors of R rays from ONE image (the scale-and-shift system is per image, never across
images: a pitfall in REFERENCE.md).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F


def color_loss(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """L1 colour loss, mean over rays and channels. pred, target: (R, 3)."""
    return (pred - target).abs().mean()


def eikonal_loss(grad: torch.Tensor) -> torch.Tensor:
    """mean (|grad| - 1)^2 over points. grad: (P, 3)."""
    return ((grad.norm(dim=-1) - 1.0) ** 2).mean()


def smoothness_loss(grad: torch.Tensor, grad_neighbour: torch.Tensor) -> torch.Tensor:
    """UNISURF / MonoSDF smoothness: mean |n(x) - n(x + jitter)| of the unit normals of points and their
    jittered neighbours (normals = grad / (|grad| + 1e-5), MonoSDF's guard). grad, grad_neighbour: (P, 3)."""
    n1 = grad / (grad.norm(dim=-1, keepdim=True) + 1e-5)
    n2 = grad_neighbour / (grad_neighbour.norm(dim=-1, keepdim=True) + 1e-5)
    return (n1 - n2).norm(dim=-1).mean()


def solve_scale_shift(pred: torch.Tensor, target: torch.Tensor, weight: torch.Tensor, eps: float = 1e-8) -> tuple[torch.Tensor, torch.Tensor]:
    """Closed-form weighted least squares ``min_{s,t} sum w (s * pred + t - target)^2`` (MiDaS / MonoSDF).

    The 2 x 2 normal equations are solved explicitly; when the determinant is (near) zero - a
    constant ``pred``, fewer than 2 weighted rays - both are 0 (MonoSDF's behaviour), which makes the
    loss constant: finite, zero gradient. Differentiable (gradients flow through s and t).

    Args:
        pred, target, weight: (R,).

    Returns:
        (scale, shift) scalars.
    """
    a00 = (weight * pred * pred).sum()
    a01 = (weight * pred).sum()
    a11 = weight.sum()
    b0 = (weight * pred * target).sum()
    b1 = (weight * target).sum()
    det = a00 * a11 - a01 * a01
    ok = det.abs() > eps * (a00 * a11).abs().clamp_min(eps)
    safe_det = torch.where(ok, det, torch.ones_like(det))
    scale = torch.where(ok, (a11 * b0 - a01 * b1) / safe_det, torch.zeros_like(det))
    shift = torch.where(ok, (-a01 * b0 + a00 * b1) / safe_det, torch.zeros_like(det))
    return scale, shift


def ssi_depth_fit(pred: torch.Tensor, target: torch.Tensor, weight: torch.Tensor,
                  negative_scale: str = "keep", fixed_scale: float | None = None) -> tuple[torch.Tensor, torch.Tensor]:
    """Scale-and-shift-invariant depth loss (MonoSDF) and its fitted scale: align the rendered depth to
    the prior in closed form, then the weighted mean squared residual in prior units.

    Args:
        pred: (R,) rendered z-depth; target: (R,) monocular prior (0 = invalid); weight: (R,) per-ray
            weights in [0, 1] (1 for MonoSDF; MonoInstance's certainty 1 - U), zeroed where invalid.
        negative_scale: ``"keep"`` (MonoSDF) or ``"drop"``: a fit with scale <= 0 (the rendered depth
            anti-correlated with the prior, e.g. the initial sphere early in training) gives loss 0 for
            this batch, instead of a gradient that pushes the depth towards the mirrored (negative-scale)
            solution, which the scale-and-shift-invariant loss rates as good as the right one.
        fixed_scale: a DIAGNOSTIC, not MonoSDF: no fit, ``scale = fixed_scale`` and shift 0 (a metric
            depth loss; meaningful only for a metric prior such as the exact GT depth, with the scene's
            metres per normalised unit). It tests whether the scale-and-shift ambiguity is what holds a
            run back (docs/studies/monosdf-scale-and-shift-ambiguity.md).

    Returns:
        (scalar loss (0 when no ray is valid), the fitted scale (detached)).
    """
    w = weight * (target > 0).to(weight.dtype)
    if fixed_scale is None:
        s, t = solve_scale_shift(pred, target, w)
    else:
        s, t = torch.tensor(float(fixed_scale), dtype=pred.dtype), torch.zeros((), dtype=pred.dtype)
    res = s * pred + t - target
    loss = (w * res * res).sum() / w.sum().clamp_min(1.0)
    if negative_scale == "drop":
        loss = torch.where(s > 0, loss, torch.zeros_like(loss))
    elif negative_scale != "keep":
        raise ValueError(f"negative_scale must be 'keep' or 'drop', got {negative_scale!r}")
    return loss, s.detach()


def ssi_depth_fit_code(pred: torch.Tensor, target: torch.Tensor, weight: torch.Tensor, crosses: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """The official MonoInstance release's form of the depth loss (``model/loss.py``): the scale and shift
    are fitted over a BINARY mask (rays whose SDF changes sign along them, with rendered and prior depth
    > 0), the squared residual is weighted by the per-ray certainty and divided by 2 x the number of
    masked rays (MiDaS' ``mse_loss``); 0 when no ray is masked or every weight is 0.

    Args:
        pred, target, weight: (R,) as in :func:`ssi_depth_fit`. crosses: (R,) bool, the SDF changes sign
            along the ray.

    Returns:
        (scalar loss, the fitted scale (detached)).
    """
    mask = (crosses & (pred > 0) & (target > 0)).to(pred.dtype)
    s, t = solve_scale_shift(pred, target, mask)
    res = s * pred + t - target
    loss = (mask * weight * res * res).sum() / (2.0 * mask.sum()).clamp_min(1.0)
    if float(weight.sum()) == 0.0:
        loss = loss * 0.0  # the release skips the term; kept in the graph with a zero gradient
    return loss, s.detach()


def ssi_depth_loss(pred: torch.Tensor, target: torch.Tensor, weight: torch.Tensor) -> torch.Tensor:
    """:func:`ssi_depth_fit`'s loss with MonoSDF's behaviour (every fitted scale kept)."""
    return ssi_depth_fit(pred, target, weight)[0]


def normal_loss(pred: torch.Tensor, target: torch.Tensor, weight: torch.Tensor, reduce: str = "weighted") -> tuple[torch.Tensor, torch.Tensor]:
    """MonoSDF's normal loss terms, per-ray weighted: (L1 of the difference summed over xyz, 1 - cos).

    Args:
        pred: (R, 3) rendered normals (any length; normalised here), camera frame.
        target: (R, 3) prior normals, camera frame (0 = invalid).
        weight: (R,) per-ray weights.
        reduce: ``"weighted"``: sums over the valid rays / the sum of their weights (MonoSDF's mean when every
            weight is 1); ``"rays"``: the MonoInstance release's ``mean(weight * term)`` over ALL rays (the
            certainty scales the terms down instead of being renormalised; no validity mask).

    Returns:
        (l1, angular) scalars.
    """
    p = F.normalize(pred, dim=-1, eps=1e-8)
    q = F.normalize(target, dim=-1, eps=1e-8)
    l1, ang = (p - q).abs().sum(-1), 1.0 - (p * q).sum(-1)
    if reduce == "rays":
        return (weight * l1).mean(), (weight * ang).mean()
    if reduce != "weighted":
        raise ValueError(f"reduce must be 'weighted' or 'rays', got {reduce!r}")
    w = weight * (target.norm(dim=-1) > 0.5).to(weight.dtype)
    denom = w.sum().clamp_min(1.0)
    return (w * l1).sum() / denom, (w * ang).sum() / denom
