"""Differentiable 3D Gaussian rasteriser for the CPU: the PyTorch path, and the entry point of the C++ one.

``kernel="cpp"`` (the default for float32) runs the projection and steps 2-6 as C++ kernels with hand-derived
backwards (:mod:`methods.gaussians.raster_kernel`); the PyTorch ops below (``kernel="torch"``, and float64)
are their twin in the tests. The algorithm below is what both compute.

Conventions (as everywhere in the project, see ``bench/data/scene.py``): ``viewmat`` is the (4, 4)
WORLD-TO-CAMERA matrix with OpenCV axes (x right, y down, z forward), world units metres; ``K`` is the
(3, 3) pinhole matrix in pixels with pixel centres at integer coordinates, so pixel (row v, column u)
is the image point (u, v). Depth outputs are z-depth.

Algorithm (sort-then-scatter; no tiles, no CUDA):

1. **Projection** (per Gaussian, computed in float64 for stability, then cast to the input dtype):
   ``t = R_cw mu + t_cw``; Gaussians with ``t_z <= near`` (behind the camera or on the near plane) or
   with a non-finite projection are culled. EWA: ``Sigma = R(q) S S^T R(q)^T`` (scales clamped to
   ``[0, max_scale]``), ``Sigma_cam = R_cw Sigma R_cw^T``, the Jacobian of the perspective map
   ``J = [[fx/z, 0, -fx x/z^2], [0, fy/z, -fy y/z^2]]`` with ``x/z, y/z`` clamped to 1.3 x the field of
   view (as 3DGS does, so Gaussians near the image border do not explode), and
   ``Sigma_2d = J Sigma_cam J^T + eps2d I`` (3DGS's 0.3 px^2 low-pass dilation: a zero-scale Gaussian
   still covers about one pixel). ``conic = Sigma_2d^-1``.
2. **Culling by screen extent**: each Gaussian covers the axis-aligned box of its 3-sigma ellipse,
   ``|u - u0| <= 3 sqrt(Sigma_2d[0, 0])``, ``|v - v0| <= 3 sqrt(Sigma_2d[1, 1])``, clipped to the image.
   Candidate (Gaussian, pixel) pairs are generated only inside these boxes, in row bands bounded by
   ``max_pairs`` candidates each, so memory and time grow with the pixel-Gaussian overlaps, not with
   pixels x Gaussians.
3. **Alpha** per pair: ``alpha = min(0.99, o exp(-0.5 d^T conic d))``; pairs with ``alpha < 1/255``
   are dropped (3DGS's rule).
4. **Sort** pairs by (pixel, depth) (one int64 key sort; ties in depth broken by Gaussian index).
5. **Front-to-back compositing**: ``T_i = prod_{j<i} (1 - alpha_j)`` within each pixel segment, as
   ``exp`` of a segmented exclusive cumulative sum of ``log(1 - alpha)`` (accumulated in float64 so
   that long pair lists do not lose precision). **Transmittance cut-off** (3DGS): a pair contributes
   only if ``T_i (1 - alpha_i) >= t_min`` (1e-4); the pixel stops at the first pair that would take it
   below. Pairs past the cut-off are removed before the differentiable pass (exact: a pair's
   transmittance depends only on the pairs in front of it).
6. **Scatter**: ``w_i = alpha_i T_i``; colour ``= sum w_i c_i + T_final * background``, depth
   ``= sum w_i z_i`` (accumulated z-depth of the Gaussian centres; divide by alpha for the expected
   depth), alpha ``= sum w_i``.

Steps 2-5 first run without autograd to select the surviving pairs; the differentiable pass then
recomputes alpha, the transmittance and the scatter on those pairs only, so the autograd graph holds
O(surviving pairs) tensors. Gradients flow to means, quaternions, scales, opacities and colours
(checked against finite differences by ``torch.autograd.gradcheck`` in float64 and against the slow
twin :mod:`methods.gaussians.rasterize_reference` in the tests).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from methods.gaussians.raster_kernel import composite_cpp, project_cpp, raster_kernel_available

ALPHA_MIN = 1.0 / 255.0
ALPHA_MAX = 0.99
T_MIN = 1e-4


@dataclass
class Projection:
    """Per-Gaussian screen-space quantities of the visible Gaussians.

    Attributes:
        ids: (M,) int64 indices of the visible Gaussians into the input arrays.
        means2d: (N, 2) pixel coordinates (u, v) of every input Gaussian (0 for culled ones); a
            non-leaf tensor: call ``retain_grad()`` on it to read the screen-space gradients the
            densification strategy uses.
        conics: (M, 3) ``(A, B, C)`` of the inverse 2D covariance ``[[A, B], [B, C]]``.
        depths: (M,) camera z of the centres (metres).
        extents: (M, 2) half-widths of the 3-sigma boxes in pixels (x, y).
        radii: (N,) float max 3-sigma half-width in pixels (0 for culled Gaussians).
    """

    ids: torch.Tensor
    means2d: torch.Tensor
    conics: torch.Tensor
    depths: torch.Tensor
    extents: torch.Tensor
    radii: torch.Tensor


def quat_to_rotmat(quats: torch.Tensor) -> torch.Tensor:
    """(..., 4) quaternions ``(w, x, y, z)`` (any norm; zero gives the identity) -> (..., 3, 3) rotations."""
    n = quats.norm(dim=-1, keepdim=True)
    ident = torch.tensor([1.0, 0.0, 0.0, 0.0], dtype=quats.dtype, device=quats.device)
    q = torch.where(n > 1e-12, quats / n.clamp_min(1e-12), ident)
    w, x, y, z = q.unbind(-1)
    return torch.stack([
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    ], dim=-1).reshape(q.shape[:-1] + (3, 3))


def project_gaussians(means: torch.Tensor, quats: torch.Tensor, scales: torch.Tensor, viewmat: torch.Tensor, K: torch.Tensor,
                      width: int, height: int, near: float = 0.01, eps2d: float = 0.3, max_scale: float = 1e3,
                      kernel: str = "torch") -> Projection:
    """EWA projection of 3D Gaussians (step 1 of the module docstring).

    Args:
        means: (N, 3) world centres (metres). quats: (N, 4) ``(w, x, y, z)``. scales: (N, 3) standard
            deviations along the local axes (metres, >= 0; clamped to ``max_scale``).
        viewmat: (4, 4) world-to-camera (OpenCV axes). K: (3, 3) intrinsics in pixels.
        width, height: image size in pixels. near: near plane (metres); ``z <= near`` is culled.
        eps2d: dilation of the 2D covariance in px^2. max_scale: upper clamp of the scales (metres).
        kernel: ``"torch"`` (the PyTorch ops below) or ``"cpp"`` (the same float64 arithmetic per Gaussian in
            C++ with a hand-derived backward, :func:`methods.gaussians.raster_kernel.project_cpp`; float32
            inputs and a camera without gradients only, else the PyTorch ops).
    """
    dtype = means.dtype
    f64 = torch.float64
    vm = viewmat.to(f64)
    Kd = K.to(f64)
    R, t = vm[:3, :3], vm[:3, 3]
    with torch.no_grad():
        zc = means.detach().to(f64) @ R[2] + t[2]
        visible = torch.isfinite(zc) & (zc > near)
        visible &= torch.isfinite(means.detach()).all(-1) & torch.isfinite(scales.detach()).all(-1) & torch.isfinite(quats.detach()).all(-1)
    ids = torch.nonzero(visible).squeeze(1)
    fx, fy, cx, cy = Kd[0, 0], Kd[1, 1], Kd[0, 2], Kd[1, 2]
    # limits of the view-ray slope for the perspective Jacobian (3DGS's clamp)
    lim_xp = ((width - 1 - cx) / fx + 0.3 * width / fx).item()
    lim_xn = (cx / fx + 0.3 * width / fx).item()
    lim_yp = ((height - 1 - cy) / fy + 0.3 * height / fy).item()
    lim_yn = (cy / fy + 0.3 * height / fy).item()
    if _use_cpp(kernel, (means, quats, scales), viewmat, K):
        cam = torch.cat([R.reshape(9), t, torch.stack([fx, fy, cx, cy]),
                         torch.tensor([lim_xn, lim_xp, lim_yn, lim_yp, eps2d, max_scale], dtype=f64)])
        means2d_vis, conics, z, ext = project_cpp(_rows(means, ids), _rows(quats, ids), _rows(scales, ids), cam)
    else:
        m = _rows(means, ids).to(f64)
        pc = m @ R.T + t  # [M, 3]
        x, y, z = pc.unbind(-1)
        # 3D covariance in the camera frame
        rot = quat_to_rotmat(_rows(quats, ids).to(f64))  # [M, 3, 3]
        s = _rows(scales, ids).to(f64).clamp(0.0, max_scale)
        M_ = R @ rot * s[:, None, :]  # [M, 3, 3] = R_cw R(q) S
        cov_cam = M_ @ M_.transpose(1, 2)
        # perspective Jacobian with the clamped view-ray slope
        tx = z * (x / z).clamp(-lim_xn, lim_xp)
        ty = z * (y / z).clamp(-lim_yn, lim_yp)
        zero = torch.zeros_like(z)
        J = torch.stack([fx / z, zero, -fx * tx / (z * z), zero, fy / z, -fy * ty / (z * z)], -1).reshape(-1, 2, 3)
        cov2d = J @ cov_cam @ J.transpose(1, 2)
        a = cov2d[:, 0, 0] + eps2d
        b = cov2d[:, 0, 1]
        c = cov2d[:, 1, 1] + eps2d
        det = (a * c - b * b).clamp_min(1e-12)
        conics = torch.stack([c / det, -b / det, a / det], -1)
        u = fx * x / z + cx
        v = fy * y / z + cy
        means2d_vis = torch.stack([u, v], -1)
        ext = 3.0 * torch.stack([a, c], -1).sqrt()
    N = means.shape[0]
    if ids.numel() == N:  # every Gaussian visible (the usual case): no scatter
        means2d = means2d_vis.to(dtype)
        radii = ext.detach().max(-1).values.to(dtype)
    else:
        means2d = torch.zeros(N, 2, dtype=dtype, device=means.device).index_copy(0, ids, means2d_vis.to(dtype))
        radii = torch.zeros(N, dtype=dtype, device=means.device)
        radii[ids] = ext.detach().max(-1).values.to(dtype)
    return Projection(ids=ids, means2d=means2d, conics=conics.to(dtype), depths=z.to(dtype), extents=ext.detach(), radii=radii)


def _use_cpp(kernel: str, tensors: tuple[torch.Tensor, ...], viewmat: torch.Tensor, K: torch.Tensor) -> bool:
    """The C++ path runs when asked for, on float32 CPU Gaussians, for a camera without gradients, if it compiled."""
    return (kernel == "cpp" and all(t.dtype == torch.float32 and t.device.type == "cpu" for t in tensors)
            and not (viewmat.requires_grad or K.requires_grad) and raster_kernel_available())


def _rows(x: torch.Tensor, ids: torch.Tensor) -> torch.Tensor:
    """``x[ids]``, or ``x`` itself when ``ids`` is every row in order (all Gaussians visible: no gather and no
    scatter in the backward)."""
    return x if ids.numel() == x.shape[0] else x[ids]


def _candidate_pairs(u0: torch.Tensor, v0: torch.Tensor, ext: torch.Tensor, width: int, row_lo: int, row_hi: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """(local Gaussian index, pixel x, pixel y) of every pixel centre inside each Gaussian's 3-sigma box
    within rows ``[row_lo, row_hi)``. All int64, Gaussian-major order."""
    xmin = torch.ceil(u0 - ext[:, 0]).clamp(0, width - 1)
    xmax = torch.floor(u0 + ext[:, 0]).clamp(-1, width - 1)
    ymin = torch.ceil(v0 - ext[:, 1]).clamp(row_lo, row_hi - 1)
    ymax = torch.floor(v0 + ext[:, 1]).clamp(row_lo - 1, row_hi - 1)
    wx = (xmax - xmin + 1).clamp_min(0).long()
    wy = (ymax - ymin + 1).clamp_min(0).long()
    # Gaussians entirely outside the image are empty boxes (xmin > xmax after clipping)
    wx = torch.where((u0 + ext[:, 0] < 0) | (u0 - ext[:, 0] > width - 1), torch.zeros_like(wx), wx)
    wy = torch.where((v0 + ext[:, 1] < row_lo) | (v0 - ext[:, 1] > row_hi - 1), torch.zeros_like(wy), wy)
    counts = wx * wy
    total = int(counts.sum())
    g = torch.repeat_interleave(torch.arange(counts.numel()), counts, output_size=total)
    start = torch.cumsum(counts, 0) - counts
    off = torch.arange(total) - start[g]
    wg = wx[g]
    px = xmin.long()[g] + off % wg
    py = ymin.long()[g] + torch.div(off, wg, rounding_mode="floor")
    return g, px, py


def _pair_alpha(dx: torch.Tensor, dy: torch.Tensor, conic: torch.Tensor, opac: torch.Tensor) -> torch.Tensor:
    power = -0.5 * (conic[:, 0] * dx * dx + conic[:, 2] * dy * dy) - conic[:, 1] * dx * dy
    return (opac * torch.exp(power.clamp_max(0.0))).clamp_max(ALPHA_MAX)


def _segment_exclusive_logT(log1m: torch.Tensor, pix: torch.Tensor) -> torch.Tensor:
    """Exclusive cumulative sum of ``log1m`` restarting at each new value of the sorted ``pix`` (float64)."""
    l64 = log1m.to(torch.float64)
    cs = torch.cumsum(l64, 0)
    excl = cs - l64
    if pix.numel() == 0:
        return excl
    is_start = torch.ones_like(pix, dtype=torch.bool)
    is_start[1:] = pix[1:] != pix[:-1]
    first = torch.where(is_start, torch.arange(pix.numel()), torch.zeros_like(pix))
    first = torch.cummax(first, 0).values
    return excl - excl[first]


def rasterize_gaussians(means: torch.Tensor, quats: torch.Tensor, scales: torch.Tensor, opacities: torch.Tensor, colors: torch.Tensor,
                        viewmat: torch.Tensor, K: torch.Tensor, width: int, height: int, background: torch.Tensor | None = None,
                        near: float = 0.01, eps2d: float = 0.3, t_min: float = T_MIN, max_pairs: int = 4_000_000,
                        max_scale: float = 1e3, kernel: str = "cpp") -> dict[str, torch.Tensor | Projection | int]:
    """Render colour, z-depth and alpha of N 3D Gaussians in one pinhole view (see the module docstring).

    Args:
        means: (N, 3) world centres, metres.
        quats: (N, 4) rotations ``(w, x, y, z)``, any norm.
        scales: (N, 3) standard deviations (metres, activated: >= 0).
        opacities: (N,) in [0, 1] (activated).
        colors: (N, C) per-Gaussian colours for this view (e.g. SH evaluated), C >= 1.
        viewmat: (4, 4) world-to-camera, OpenCV axes. K: (3, 3) pixels.
        width, height: image size (pixels).
        background: (C,) colour behind everything (default 0).
        near: near plane (metres). eps2d: 2D dilation (px^2). t_min: transmittance cut-off.
        max_pairs: bound on the candidate pairs generated at once (row bands are processed separately; both paths).
        kernel: ``"cpp"`` (default): steps 2-6 in one C++ pass per pixel (:mod:`methods.gaussians.raster_kernel`,
            float32, camera without gradients; else, and without a compiler, the PyTorch path); ``"torch"``: the PyTorch path below,
            the kernel's twin.

    Returns:
        dict with ``color`` (H, W, C), ``depth`` (H, W) accumulated z-depth ``sum w z``, ``alpha`` (H, W)
        ``sum w``, ``proj`` (:class:`Projection`), ``n_pairs`` (contributing pairs) and ``n_candidates``.
    """
    if kernel not in ("cpp", "torch"):
        raise ValueError(f"kernel must be 'cpp' or 'torch', got {kernel!r}")
    if not t_min > 0:
        raise ValueError(f"t_min must be > 0, got {t_min}")
    if means.ndim != 2 or means.shape[1] != 3:
        raise ValueError(f"means must be (N, 3), got {tuple(means.shape)}")
    N = means.shape[0]
    for name, arr, shp in (("quats", quats, (N, 4)), ("scales", scales, (N, 3)), ("opacities", opacities, (N,))):
        if tuple(arr.shape) != shp:
            raise ValueError(f"{name} must be {shp}, got {tuple(arr.shape)}")
    if colors.ndim != 2 or colors.shape[0] != N:
        raise ValueError(f"colors must be (N, C) with N = {N}, got {tuple(colors.shape)}")
    dtype = means.dtype
    C = colors.shape[1]
    HW = width * height
    proj = project_gaussians(means, quats, scales, viewmat, K, width, height, near=near, eps2d=eps2d, max_scale=max_scale, kernel=kernel)
    ids = proj.ids
    M = ids.numel()
    opac_v = _rows(opacities, ids)
    col_v = _rows(colors, ids)
    m2d_v = _rows(proj.means2d, ids)
    if _use_cpp(kernel, (means, quats, scales, opacities, colors), viewmat, K):
        out, n_pairs, n_cand = composite_cpp(m2d_v, proj.conics, opac_v, proj.depths, col_v, proj.extents.to(dtype), width, height, t_min,
                                             max_pairs)
        return _outputs(out, background, proj, n_pairs, n_cand, width, height)
    # depth rank (stable) so the sort key is (pixel, depth, index)
    with torch.no_grad():
        order = torch.sort(proj.depths.detach(), stable=True).indices
        rank = torch.empty_like(order)
        rank[order] = torch.arange(M)
        u0 = m2d_v[:, 0].detach()
        v0 = m2d_v[:, 1].detach()
        ext = proj.extents.to(dtype)
        xw = (torch.floor(u0 + ext[:, 0]).clamp(-1, width - 1) - torch.ceil(u0 - ext[:, 0]).clamp(0, width - 1) + 1).clamp_min(0)
        yw = (torch.floor(v0 + ext[:, 1]).clamp(-1, height - 1) - torch.ceil(v0 - ext[:, 1]).clamp(0, height - 1) + 1).clamp_min(0)
        est = float((xw * yw).sum()) if M else 0.0
        n_bands = max(1, min(height, math.ceil(est / max_pairs)))
    bands = [(round(b * height / n_bands), round((b + 1) * height / n_bands)) for b in range(n_bands)]
    sel_g, sel_pix = [], []
    n_cand = 0
    with torch.no_grad():
        # per-Gaussian attributes packed in one row each: one gather per pair instead of six
        attrs = torch.cat([u0[:, None], v0[:, None], proj.conics.detach(), opac_v.detach()[:, None]], 1)  # [M, 6]
        for lo, hi in bands:
            if M == 0 or hi <= lo:
                continue
            g, px, py = _candidate_pairs(u0, v0, ext, width, lo, hi)
            n_cand += g.numel()
            a = attrs.index_select(0, g)
            alpha = _pair_alpha(px.to(dtype) - a[:, 0], py.to(dtype) - a[:, 1], a[:, 2:5], a[:, 5])
            keep = torch.nonzero(alpha >= ALPHA_MIN).squeeze(1)
            g, alpha = g.index_select(0, keep), alpha.index_select(0, keep)
            pix = py.index_select(0, keep) * width + px.index_select(0, keep)
            srt = torch.sort(pix * M + rank.index_select(0, g)).indices
            g, pix, alpha = g.index_select(0, srt), pix.index_select(0, srt), alpha.index_select(0, srt)
            log1m = torch.log1p(-alpha)
            logT_after = _segment_exclusive_logT(log1m, pix) + log1m.to(torch.float64)
            # T is monotone within a pixel, so "T after this pair >= t_min" keeps a prefix per pixel:
            # the cut-off latches once a pixel has stopped
            ok = torch.nonzero(logT_after >= math.log(t_min)).squeeze(1)
            sel_g.append(g.index_select(0, ok))
            sel_pix.append(pix.index_select(0, ok))
    g = torch.cat(sel_g) if sel_g else torch.zeros(0, dtype=torch.long)
    pix = torch.cat(sel_pix) if sel_pix else torch.zeros(0, dtype=torch.long)
    # differentiable pass on the surviving pairs: one packed gather [P, 7 + C]
    packed = torch.cat([m2d_v, proj.conics, opac_v[:, None], proj.depths[:, None], col_v], 1)
    gu, gv, cA, cB, cC, op, gz, *gc = packed.index_select(0, g).unbind(1)  # unbind: one stack in backward
    dx = (pix % width).to(dtype) - gu
    dy = torch.div(pix, width, rounding_mode="floor").to(dtype) - gv
    power = (-0.5 * (cA * dx * dx + cC * dy * dy) - cB * dx * dy).clamp_max(0.0)
    alpha = (op * torch.exp(power)).clamp_max(ALPHA_MAX)
    T = torch.exp(_segment_exclusive_logT(torch.log1p(-alpha), pix)).to(dtype)
    w = alpha * T
    out = torch.zeros(HW, 2 + C, dtype=dtype).index_add(0, pix, torch.stack([w, w * gz] + [w * c for c in gc], 1))
    return _outputs(out, background, proj, int(g.numel()), n_cand, width, height)


def _outputs(out: torch.Tensor, background: torch.Tensor | None, proj: Projection, n_pairs: int, n_cand: int, width: int,
             height: int) -> dict[str, torch.Tensor | Projection | int]:
    """The result dict from the (HW, 2 + C) per-pixel rows ``[sum w, sum w z, sum w c]`` (step 6's background)."""
    acc, dep, col = out[:, 0], out[:, 1], out[:, 2:]
    if background is not None:
        col = col + (1.0 - acc)[:, None] * background.to(out.dtype)[None, :]
    return {"color": col.reshape(height, width, -1), "depth": dep.reshape(height, width), "alpha": acc.reshape(height, width),
            "proj": proj, "n_pairs": n_pairs, "n_candidates": n_cand}
