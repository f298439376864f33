"""The rasteriser's screen-space part (steps 2-6 of :mod:`methods.gaussians.rasterize`) as a C++ kernel.

``_raster_kernel.cpp`` composites every pixel front to back over the depth-sorted Gaussians whose 3-sigma box
holds it, and has hand-derived backwards (also for the EWA projection); it computes what the PyTorch path of ``rasterize.py`` computes (the same
float32 operations in the same order, the same pair selection up to an ulp of ``exp``: glibc's here, SLEEF's
in PyTorch), which stays as its tested twin and as the fallback without a compiler. Gradients reach the
Gaussians only (not the camera: ``rasterize_gaussians`` takes the PyTorch path for a camera that needs them);
no double backward. Compiled on first use without ``-ffast-math`` and with ``-ffp-contract=off``:
no fused or reordered arithmetic. The kernel keeps the transmittance as a float64 running product where the
twin exponentiates a float64 sum of float32 ``log1p(-alpha)``: the two agree to float32 rounding (tests).
"""

from __future__ import annotations

from types import ModuleType

import torch
from torch.autograd.function import once_differentiable

from methods.cpp_build import CppExtension

_KERNEL = CppExtension("gaussians_raster_kernel", __file__, ("_raster_kernel.cpp",),
                       cflags=("-O3", "-march=native", "-ffp-contract=off"))


def raster_kernel_available() -> bool:
    """True if the C++ rasteriser compiled and loaded."""
    return _KERNEL.load() is not None


def _loaded() -> ModuleType:
    """The loaded extension (callers check :func:`raster_kernel_available` first)."""
    ext = _KERNEL.load()
    assert ext is not None
    return ext


class _RasterFunction(torch.autograd.Function):
    """Autograd wrapper: forward and backward of the screen-space pass (see ``_raster_kernel.cpp``)."""

    @staticmethod
    def forward(ctx, means2d: torch.Tensor, conics: torch.Tensor, opacities: torch.Tensor, depths: torch.Tensor,  # type: ignore[override]
                colors: torch.Tensor, extents: torch.Tensor, width: int, height: int, t_min: float, max_pairs: int):
        ext = _loaded()
        args = [t.detach().contiguous() for t in (means2d, conics, opacities, depths, colors)]
        out, slot_g, slot_a, slot_T, pix_start, pix_count, stats = ext.raster_forward(*args, extents.contiguous(),
                                                                                      width, height, t_min, max_pairs)
        ctx.save_for_backward(*args, slot_g, slot_a, slot_T, pix_start, pix_count)
        ctx.width = width
        ctx.mark_non_differentiable(stats)
        return out, stats

    @staticmethod
    @once_differentiable
    def backward(ctx, grad_out: torch.Tensor, _grad_stats: torch.Tensor):  # type: ignore[override]
        ext = _loaded()
        grads = ext.raster_backward(grad_out.contiguous(), *ctx.saved_tensors, ctx.width)
        return (*grads, None, None, None, None, None)


def composite_cpp(means2d: torch.Tensor, conics: torch.Tensor, opacities: torch.Tensor, depths: torch.Tensor, colors: torch.Tensor,
                  extents: torch.Tensor, width: int, height: int, t_min: float, max_pairs: int) -> tuple[torch.Tensor, int, int]:
    """Composite M projected Gaussians into a ``width`` x ``height`` image (float32, differentiable).

    Args:
        means2d: (M, 2) pixel centres (u, v). conics: (M, 3) ``(A, B, C)`` of the inverse 2D covariance.
        opacities: (M,) in [0, 1]. depths: (M,) camera z (metres; composited front to back, ties by index). colors: (M, C).
        extents: (M, 2) half-widths of the 3-sigma boxes in pixels. t_min: transmittance cut-off (> 0).
        max_pairs: candidate pairs per row band (the bands run one after another: bounded memory; one row at least).

    Returns:
        (HW, 2 + C) rows ``[sum w, sum w z, sum w c]`` per pixel (row-major pixels), the number of
        contributing pairs and the number of candidate pairs (pixel centres inside the boxes).
    """
    out, stats = _RasterFunction.apply(means2d, conics, opacities, depths, colors, extents, width, height, t_min, max_pairs)
    return out, int(stats[0]), int(stats[1])


class _ProjectFunction(torch.autograd.Function):
    """Autograd wrapper of the EWA projection kernel (``project_forward`` / ``project_backward``)."""

    @staticmethod
    def forward(ctx, means: torch.Tensor, quats: torch.Tensor, scales: torch.Tensor, cam: torch.Tensor):  # type: ignore[override]
        ext = _loaded()
        args = [t.detach().contiguous() for t in (means, quats, scales)]
        m2d, conics, depths, extents = ext.project_forward(*args, cam.contiguous())
        ctx.save_for_backward(*args, cam)
        ctx.mark_non_differentiable(extents)
        return m2d, conics, depths, extents

    @staticmethod
    @once_differentiable
    def backward(ctx, g_m2d: torch.Tensor, g_conics: torch.Tensor, g_depths: torch.Tensor, _g_ext: torch.Tensor):  # type: ignore[override]
        ext = _loaded()
        means, quats, scales, cam = ctx.saved_tensors
        grads = ext.project_backward(g_m2d.contiguous(), g_conics.contiguous(), g_depths.contiguous(), means, quats, scales, cam)
        return (*grads, None)


def project_cpp(means: torch.Tensor, quats: torch.Tensor, scales: torch.Tensor,
                cam: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """EWA projection of M visible Gaussians (float32 in, float64 inside; differentiable).

    Args:
        means: (M, 3) world centres (metres). quats: (M, 4) ``(w, x, y, z)``. scales: (M, 3) (metres).
        cam: (22,) float64 ``[R_cw (9, row-major), t_cw (3), fx, fy, cx, cy, lim_xn, lim_xp, lim_yn, lim_yp,
            eps2d, max_scale]`` (world-to-camera, OpenCV axes; the slope limits of the perspective Jacobian).

    Returns:
        means2d (M, 2) pixels, conics (M, 3), depths (M,) camera z (float32), extents (M, 2) 3-sigma
        half-widths in pixels (float64, not differentiable).
    """
    return _ProjectFunction.apply(means, quats, scales, cam)
