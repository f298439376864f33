"""Slow, obviously-correct twin of :func:`methods.gaussians.rasterize.rasterize_gaussians`.

Same inputs, outputs and conventions (world-to-camera ``viewmat``, OpenCV axes, integer pixel
centres, z-depth). Written for reading, not speed: each Gaussian is projected on its own with explicit
3 x 3 matrices, and the image is composited by a Python loop over the Gaussians in depth order,
evaluating every Gaussian at EVERY pixel (O(N x H x W)). The rules it implements, one line each:

* a Gaussian is culled if its camera z <= near;
* ``Sigma_2d = J W Sigma W^T J^T + eps2d I`` with the 1.3 x field-of-view clamp of x/z, y/z in J;
* a pixel is covered only inside the 3-sigma box ``|du| <= 3 sqrt(Sigma_2d[0,0])``,
  ``|dv| <= 3 sqrt(Sigma_2d[1,1])``;
* ``alpha = min(0.99, o exp(-0.5 d^T Sigma_2d^-1 d))``; alpha < 1/255 is skipped;
* front to back: a pixel stops (this Gaussian excluded) when ``T (1 - alpha) < t_min``;
  otherwise ``C += alpha T c``, ``D += alpha T z``, ``A += alpha T``, ``T *= 1 - alpha``.

Use only for tests on tiny cases (a few Gaussians, a few hundred pixels).
"""

from __future__ import annotations

import torch

from methods.gaussians.rasterize import ALPHA_MAX, ALPHA_MIN, T_MIN, quat_to_rotmat


def rasterize_gaussians_reference(means, quats, scales, opacities, colors, viewmat, K, width: int, height: int, background=None,
                                  near: float = 0.01, eps2d: float = 0.3, t_min: float = T_MIN, max_scale: float = 1e3) -> dict[str, torch.Tensor]:
    """Reference rendering; returns ``color`` (H, W, C), ``depth`` (H, W), ``alpha`` (H, W)."""
    dtype = means.dtype
    N, C = means.shape[0], colors.shape[1]
    Rcw = viewmat[:3, :3].to(torch.float64)
    tcw = viewmat[:3, 3].to(torch.float64)
    fx, fy, cx, cy = [float(K[i, j]) for i, j in ((0, 0), (1, 1), (0, 2), (1, 2))]
    vs, us = torch.meshgrid(torch.arange(height, dtype=dtype), torch.arange(width, dtype=dtype), indexing="ij")
    projected = []
    for i in range(N):
        p = Rcw @ means[i].to(torch.float64) + tcw
        if not float(p[2].detach()) > near:
            continue
        Rq = quat_to_rotmat(quats[i].to(torch.float64))
        S = torch.diag(scales[i].to(torch.float64).clamp(0.0, max_scale))
        Sigma = Rq @ S @ S @ Rq.T
        Sigma_cam = Rcw @ Sigma @ Rcw.T
        x, y, z = p[0], p[1], p[2]
        limx_p, limx_n = (width - 1 - cx) / fx + 0.3 * width / fx, cx / fx + 0.3 * width / fx
        limy_p, limy_n = (height - 1 - cy) / fy + 0.3 * height / fy, cy / fy + 0.3 * height / fy
        tx = z * torch.clamp(x / z, -limx_n, limx_p)
        ty = z * torch.clamp(y / z, -limy_n, limy_p)
        J = torch.zeros(2, 3, dtype=torch.float64)
        J = torch.stack([torch.stack([fx / z, 0 * z, -fx * tx / z ** 2]), torch.stack([0 * z, fy / z, -fy * ty / z ** 2])])
        cov2d = J @ Sigma_cam @ J.T + eps2d * torch.eye(2, dtype=torch.float64)
        conic = torch.linalg.inv(cov2d)
        mean2d = torch.stack([fx * x / z + cx, fy * y / z + cy])
        projected.append((float(z.detach()), i, mean2d.to(dtype), conic.to(dtype), cov2d.detach(), z.to(dtype)))
    projected.sort(key=lambda e: (e[0], e[1]))
    T = torch.ones(height, width, dtype=dtype)
    done = torch.zeros(height, width, dtype=torch.bool)
    col = torch.zeros(height, width, C, dtype=dtype)
    dep = torch.zeros(height, width, dtype=dtype)
    acc = torch.zeros(height, width, dtype=dtype)
    for _, i, m2, Q, cov2d, z in projected:
        du, dv = us - m2[0], vs - m2[1]
        inside = (du.detach().abs() <= 3 * cov2d[0, 0].sqrt()) & (dv.detach().abs() <= 3 * cov2d[1, 1].sqrt())
        power = -0.5 * (Q[0, 0] * du * du + Q[1, 1] * dv * dv) - Q[0, 1] * du * dv
        alpha = torch.clamp(opacities[i] * torch.exp(torch.clamp(power, max=0.0)), max=ALPHA_MAX)
        use = inside & (alpha.detach() >= ALPHA_MIN) & ~done
        stop = use & ((T * (1 - alpha)).detach() < t_min)
        done = done | stop
        use = use & ~stop
        a = torch.where(use, alpha, torch.zeros_like(alpha))
        w = a * T
        col = col + w[..., None] * colors[i]
        dep = dep + w * z
        acc = acc + w
        T = T * (1 - a)
    if background is not None:
        col = col + T[..., None] * background.to(dtype)
    return {"color": col, "depth": dep, "alpha": acc}
