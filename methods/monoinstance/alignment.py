"""Step 1 of the MonoInstance uncertainty stage: per-view alignment of the monocular depth prior.

The prior is relative (unknown per-view scale, maybe shift). Each view is fitted by least squares to a
reference depth ``t`` (in the pipeline: the depth rendered by stage 1 of the SDF / Gaussian model; in
tests: GT depth), over the pixels ``m`` where both are valid (> 0, finite, optional ``valid`` mask):

* ``"scale"`` (official code, ``process_confidence.py``): ``s = sum(m p t) / sum(m p^2)``, ``t0 = 0``.
* ``"scale_shift"`` (paper, Sec. 3.2 "scale-shift invariant affine"): 2 x 2 normal equations for
  ``(s, t0)`` minimising ``sum m (s p + t0 - t)^2``.

The reference may be rendered at lower resolution (the code renders at 1/4 resolution): if
``ref_depth`` is (N, h, w) with h < H, the prior is subsampled as ``mono[:, ::f, ::f]`` (f = H // h,
exactly what the code does with ``uv_down``) for the fit, and the fitted (s, t0) are applied to the
full-resolution prior.

Fallback (documented, never silent in the result: see :func:`align_mono_depth_status`): a view whose
fit is impossible or absurd (fewer than ``min_pixels`` common valid pixels, singular system, or a
non-positive / non-finite scale) gets the median scale (and shift) of the views that did fit, or
(1, 0) when no view fits. ``scale_shift`` first falls back to ``scale`` for that view before using the
median. Invalid prior pixels (0 or non-finite) stay 0 in the output, so the output is always finite.
Units: metres if the reference is in metres.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

AlignMode = Literal["scale", "scale_shift"]

#: status codes per view returned by :func:`align_mono_depth_status`
STATUS_OK, STATUS_SCALE_ONLY, STATUS_FALLBACK = 0, 1, 2


def _downsample_to(mono: np.ndarray, ref_hw: tuple[int, int]) -> np.ndarray:
    h, w = mono.shape[-2:]
    rh, rw = ref_hw
    if (rh, rw) == (h, w):
        return mono
    f = h // rh if rh > 0 else 0
    if f < 1 or mono[..., ::f, ::f].shape[-2:] != (rh, rw):
        raise ValueError(
            f"ref_depth of size {rh} x {rw} is not the mono depth's {h} x {w} subsampled by an integer factor "
            "(expected mono[:, ::f, ::f] to match)"
        )
    return mono[..., ::f, ::f]


def _fit_view(p: np.ndarray, t: np.ndarray, mode: str, min_pixels: int) -> tuple[float, float, int] | None:
    """(scale, shift, status) for one view's valid pixel values, or None if no fit is possible."""
    if p.size < max(min_pixels, 1):
        return None
    if mode == "scale_shift" and p.size >= max(min_pixels, 2):
        a00, a01, a11 = float(np.sum(p * p)), float(p.sum()), float(p.size)
        b0, b1 = float(np.sum(p * t)), float(t.sum())
        det = a00 * a11 - a01 * a01
        if det > 1e-12 * max(a00 * a11, 1e-300):
            s = (a11 * b0 - a01 * b1) / det
            sh = (a00 * b1 - a01 * b0) / det
            if np.isfinite(s) and np.isfinite(sh) and s > 0:
                return s, sh, STATUS_OK
    denom = float(np.sum(p * p))  # not BLAS dot: avoids thread spin-up costs on a busy 2-core box
    if denom <= 0:
        return None
    s = float(np.sum(p * t)) / denom
    if not np.isfinite(s) or s <= 0:
        return None
    return s, 0.0, (STATUS_OK if mode == "scale" else STATUS_SCALE_ONLY)


def align_mono_depth_status(
    mono_depth: np.ndarray,
    ref_depth: np.ndarray,
    mode: AlignMode = "scale",
    valid: np.ndarray | None = None,
    border_px: int = 0,
    min_pixels: int = 10,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`align_mono_depth` plus a per-view status (0 fitted, 1 scale_shift fell back to scale,
    2 fallback to the median of the fitted views). Extra arguments:

    Args:
        border_px: pixels of the *reference-resolution* border excluded from the fit (code: 8, against
            a Metric3D border artefact at 384 px; 0 at our small image sizes).
        min_pixels: fewest common valid pixels for a fit.
    """
    mono = np.asarray(mono_depth)
    ref = np.asarray(ref_depth)
    if mono.ndim != 3 or ref.ndim != 3 or mono.shape[0] != ref.shape[0]:
        raise ValueError(f"mono_depth and ref_depth must be (N, H, W) and (N, h, w), got {mono.shape} and {ref.shape}")
    if mode not in ("scale", "scale_shift"):
        raise ValueError(f"mode must be 'scale' or 'scale_shift', got {mode!r}")
    n = mono.shape[0]
    mono64 = mono.astype(np.float64)
    p_all = _downsample_to(mono64, ref.shape[1:])
    t_all = ref.astype(np.float64)
    vmask = np.isfinite(p_all) & (p_all > 0) & np.isfinite(t_all) & (t_all > 0)
    if valid is not None:
        vm = np.asarray(valid, dtype=bool)
        if vm.shape == mono.shape:
            vm = _downsample_to(vm, ref.shape[1:])
        if vm.shape != ref.shape:
            raise ValueError(f"valid must have shape {mono.shape} or {ref.shape}, got {vm.shape}")
        vmask &= vm
    if border_px > 0:
        b = int(border_px)
        vmask[:, :b] = vmask[:, -b:] = False
        vmask[:, :, :b] = vmask[:, :, -b:] = False
    scale = np.ones(n)
    shift = np.zeros(n)
    status = np.full(n, STATUS_FALLBACK, dtype=np.int8)
    for i in range(n):
        m = vmask[i]
        fit = _fit_view(p_all[i][m], t_all[i][m], mode, min_pixels)
        if fit is not None:
            scale[i], shift[i], status[i] = fit
    ok = status != STATUS_FALLBACK
    if ok.any():
        scale[~ok] = float(np.median(scale[ok]))
        shift[~ok] = float(np.median(shift[ok]))
    prior_ok = np.isfinite(mono64) & (mono64 > 0)
    aligned = np.where(prior_ok, mono64 * scale[:, None, None] + shift[:, None, None], 0.0)
    aligned = np.where(aligned > 0, aligned, 0.0)  # a negative shift can push depths below 0: invalid
    return aligned.astype(np.float32), scale, shift, status


def align_mono_depth(
    mono_depth: np.ndarray,
    ref_depth: np.ndarray,
    mode: AlignMode = "scale",
    valid: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Align each view's monocular depth to a reference depth by least squares.

    Args:
        mono_depth: (N, H, W) relative depth prior (0 or non-finite = invalid).
        ref_depth: (N, H, W) reference z-depth (metres), or (N, H/f, W/f) rendered at 1/f resolution.
        mode: ``"scale"`` (official code, default) or ``"scale_shift"`` (paper).
        valid: optional (N, H, W) or reference-sized bool mask of pixels usable for the fit.

    Returns:
        aligned (N, H, W) float32 (``s_i p + t_i`` where the prior is valid and the result > 0, else 0;
        always finite), scale (N,) float64, shift (N,) float64 (0 in ``"scale"`` mode). Views without a
        possible fit get the median (scale, shift) of the fitted views (module docstring).
    """
    aligned, scale, shift, _ = align_mono_depth_status(mono_depth, ref_depth, mode, valid)
    return aligned, scale, shift
