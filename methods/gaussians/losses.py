"""Losses of the Gaussian variants: photometric, (weighted) Pearson depth correlation, instance-mask constraint.

All images (H, W, 3) float in [0, 1]; depth maps (H, W) z-depth in metres (rendered depth is the
alpha-accumulated ``sum w z``, as FSGS uses it); weights (H, W) >= 0.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from metrics.image import gaussian_ssim_map


def ssim_map(x: torch.Tensor, y: torch.Tensor, window: int = 11, sigma: float = 1.5) -> torch.Tensor:
    """SSIM map (valid region) of two (H, W, 3) images with a Gaussian window (C1 = 0.01^2, C2 = 0.03^2):
    :func:`metrics.image.gaussian_ssim_map` with ``padding="valid"``, shape (1, 3, H - 10, W - 10)."""
    return gaussian_ssim_map(x.permute(2, 0, 1)[None], y.permute(2, 0, 1)[None], window, sigma, padding="valid")


def photometric_loss(render: torch.Tensor, target: torch.Tensor, lambda_dssim: float = 0.2) -> torch.Tensor:
    """3DGS / FSGS RGB loss: ``(1 - lambda) L1 + lambda (1 - SSIM)``."""
    return (1.0 - lambda_dssim) * (render - target).abs().mean() + lambda_dssim * (1.0 - ssim_map(render, target).mean())


def pearson_depth_loss(depth: torch.Tensor, prior: torch.Tensor, weight: torch.Tensor | None = None, eps: float = 1e-8) -> torch.Tensor:
    """``1 - corr_w(depth, prior)``: the (optionally pixel-weighted) Pearson correlation of FSGS.

    Scale- and shift-invariant in both arguments, so the monocular prior's unknown per-view affine
    ambiguity does not matter. ``weight`` (H, W) >= 0 (default: 1 where ``prior > 0``); pixels with
    ``prior <= 0`` (invalid) always get weight 0. Returns 0 (with a graph) when the weights vanish.
    """
    w = (prior > 0).to(depth.dtype) if weight is None else weight * (prior > 0).to(depth.dtype)
    sw = w.sum()
    if float(sw) <= 0:
        return depth.sum() * 0.0
    x, y = depth, prior.to(depth.dtype)
    mx, my = (w * x).sum() / sw, (w * y).sum() / sw
    dx, dy = x - mx, y - my
    cov = (w * dx * dy).sum() / sw
    vx, vy = (w * dx * dx).sum() / sw, (w * dy * dy).sum() / sw
    return 1.0 - cov / torch.sqrt(vx * vy + eps)


def mask_constraint_loss(points_world: torch.Tensor, inst: torch.Tensor, dist_maps: dict[tuple[int, int], torch.Tensor],
                         views: list[tuple[int, torch.Tensor, torch.Tensor]], width: int, height: int) -> tuple[torch.Tensor, int]:
    """Supplementary's 3DGS mask constraint.

    A high-uncertainty pixel of instance ``k``, back-projected with the rendered depth to
    ``points_world`` (P, 3), is projected into each nearby view ``j``; if it lands inside that image and
    instance ``k`` is visible there, the penalty is the distance (in pixels / image width) from the
    projection to the nearest pixel of ``k``'s mask in view ``j`` (0 inside the mask), read from the
    precomputed distance transform ``dist_maps[(j, k)]`` (H, W) by bilinear interpolation so the gradient
    reaches the depth. ``views``: list of ``(j, K_j (3, 3), world_to_cam_j (4, 4))`` (float32).

    Returns:
        (mean penalty over the counted (pixel, view) pairs, number of counted pairs).
    """
    total = points_world.sum() * 0.0
    count = 0
    for j, Kj, w2c in views:
        pc = points_world @ w2c[:3, :3].T + w2c[:3, 3]
        z = pc[:, 2]
        front = z > 1e-3
        uv = (pc @ Kj.T)[:, :2] / z.clamp_min(1e-3)[:, None]
        inside = front & (uv[:, 0] >= 0) & (uv[:, 0] <= width - 1) & (uv[:, 1] >= 0) & (uv[:, 1] <= height - 1)
        for k in torch.unique(inst).tolist():
            dm = dist_maps.get((j, int(k)))
            if dm is None:
                continue
            sel = torch.nonzero(inside & (inst == k)).squeeze(1)
            if sel.numel() == 0:
                continue
            g = torch.stack([uv[sel, 0] / (width - 1) * 2 - 1, uv[sel, 1] / (height - 1) * 2 - 1], -1)[None, None]
            d = F.grid_sample(dm[None, None], g, mode="bilinear", align_corners=True)[0, 0, 0]
            total = total + d.sum() / width
            count += int(sel.numel())
    return (total / max(count, 1)), count
