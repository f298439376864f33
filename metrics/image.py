"""Image metrics for the few-shot novel-view table (Table 3): PSNR and SSIM through kornia.

As FSGS / RegNeRF evaluate saved PNGs, both images are first quantised to 8 bits:
``q(x) = round(clip(x, 0, 1) * 255) / 255``.

* PSNR (dB) per image: ``10 log10(1 / MSE)`` over all pixels and channels (``kornia.metrics.psnr``,
  max value 1). Identical images give MSE = 0 and an infinite PSNR: it is capped at ``max_db``
  (default 100 dB). Any image pair that is not identical after quantisation but would exceed the cap
  (a single 8-bit step on one channel of a >= 200k-pixel image) is capped too: 100 dB reads as
  "identical up to 8-bit rounding". Real reconstructions score 10-40 dB, so the cap never binds there.
* SSIM per image: an 11 x 11 Gaussian window, sigma 1.5, C1 = (0.01)^2, C2 = (0.03)^2, mean over pixels
  and channels, in one of two border conventions (``padding``):

  - ``"valid"`` (``kornia.metrics.ssim(padding="valid")``): the map is averaged only where the window
    fits, which is what scikit-image's ``structural_similarity(gaussian_weights=True, sigma=1.5,
    use_sample_covariance=False, data_range=1)`` does by cropping the border;
  - ``"zero"`` (FSGS / 3DGS ``utils/loss_utils.py``: ``F.conv2d(..., padding=window // 2)``): the moments
    are filtered with zero padding and the map is averaged over the whole image. The padded border is
    dark in both images, where they agree, so small images score higher than with ``"valid"`` (Table 3
    3DGS renders at 128 x 96: +0.025-0.030; the gap shrinks with the image size). The LLFF protocol uses
    this one (the paper's Table 3 numbers come from FSGS's evaluation; ``configs/protocols.yaml``).

  Constant images are fine (C1, C2 regularise): two equal constants give SSIM = 1.

Both return :class:`ImageScores` (per-image values and their mean).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from metrics._checks import check_int, check_positive


@dataclass(frozen=True)
class ImageScores:
    """Per-image values (N,) float64 and their mean."""

    per_image: np.ndarray
    mean: float


def quantize_8bit(images: torch.Tensor) -> torch.Tensor:
    """``round(clip(x, 0, 1) * 255) / 255`` (same shape and dtype)."""
    return torch.round(images.clamp(0.0, 1.0) * 255.0) / 255.0


def _as_batch(x: Any, name: str) -> torch.Tensor:
    """(H, W, 3) or (N, H, W, 3) float in [0, 1] -> (N, 3, H, W) float64 tensor."""
    if isinstance(x, np.ndarray):
        t = torch.from_numpy(np.ascontiguousarray(x))
    elif isinstance(x, torch.Tensor):
        t = x.detach().cpu()
    else:
        raise TypeError(f"{name} must be a numpy.ndarray or torch.Tensor, got {type(x).__name__}")
    if not torch.is_floating_point(t):
        raise TypeError(f"{name} must be float in [0, 1], got dtype {t.dtype}")
    if t.ndim == 3:
        t = t[None]
    if t.ndim != 4 or t.shape[-1] != 3 or t.shape[0] == 0:
        raise ValueError(f"{name} must have shape (H, W, 3) or (N, H, W, 3) with N >= 1, got {tuple(x.shape)}")
    if not torch.isfinite(t).all():
        raise ValueError(f"{name} contains NaN or inf")
    return t.permute(0, 3, 1, 2).to(torch.float64)


def _pair(pred: Any, target: Any) -> tuple[torch.Tensor, torch.Tensor]:
    p = _as_batch(pred, "pred")
    t = _as_batch(target, "target")
    if p.shape != t.shape:
        raise ValueError(f"pred and target shapes differ: {tuple(p.shape)} vs {tuple(t.shape)} (N, 3, H, W)")
    return p, t


def psnr(pred: Any, target: Any, quantize: bool = True, max_db: float = 100.0) -> ImageScores:
    """Peak signal-to-noise ratio per image, in dB (max value 1, on 8-bit-quantised images).

    .. math:: \\text{PSNR} = \\min(10 \\log_{10}(1 / \\text{MSE}), \\text{max\\_db})

    Args:
        pred: (N, H, W, 3) or (H, W, 3) float RGB in [0, 1] (numpy or torch).
        target: same shape.
        quantize: quantise both to 8 bits first (default, as the few-shot papers).
        max_db: cap for identical images (MSE = 0), dB.

    Returns:
        :class:`ImageScores` (per-image PSNR (N,), mean of the capped values).

    Example:
        >>> a = np.zeros((4, 4, 3)); b = a.copy(); b[0, 0, 0] = 1.0
        >>> round(psnr(b, a).mean, 3)  # MSE = 1 / 48
        16.812
    """
    p, t = _pair(pred, target)
    cap = check_positive(max_db, "max_db")
    if quantize:
        p, t = quantize_8bit(p), quantize_8bit(t)
    import kornia

    vals = []
    for i in range(p.shape[0]):
        if torch.equal(p[i], t[i]):
            vals.append(cap)
        else:
            vals.append(min(float(kornia.metrics.psnr(p[i], t[i], max_val=1.0)), cap))
    arr = np.asarray(vals, dtype=np.float64)
    return ImageScores(per_image=arr, mean=float(arr.mean()))


SSIM_PADDINGS = ("valid", "zero")


def ssim(
    pred: Any, target: Any, quantize: bool = True, window_size: int = 11, sigma: float = 1.5, padding: str = "valid"
) -> ImageScores:
    """Structural similarity per image (Gaussian 11 x 11 window, sigma 1.5).

    Args:
        pred: (N, H, W, 3) or (H, W, 3) float RGB in [0, 1]; H, W >= ``window_size``.
        target: same shape.
        quantize: quantise both to 8 bits first (default).
        window_size: odd Gaussian window size (11).
        sigma: Gaussian sigma in pixels (1.5; kornia's ssim fixes 1.5, so only 1.5 is accepted).
        padding: ``"valid"`` (scikit-image / kornia, border cropped) or ``"zero"`` (FSGS: zero padding,
            whole image); see the module docstring.

    Returns:
        :class:`ImageScores` (per-image SSIM in [-1, 1], mean).
    """
    p, t = _pair(pred, target)
    ws = check_int(window_size, "window_size", 3)
    if ws % 2 == 0:
        raise ValueError(f"window_size must be odd, got {ws}")
    if float(sigma) != 1.5:
        raise ValueError(f"sigma must be 1.5 (kornia.metrics.ssim uses a fixed sigma), got {sigma}")
    if p.shape[-1] < ws or p.shape[-2] < ws:
        raise ValueError(f"images must be at least {ws} x {ws} pixels, got {tuple(p.shape[-2:])}")
    if padding not in SSIM_PADDINGS:
        raise ValueError(f"padding must be one of {SSIM_PADDINGS}, got {padding!r}")
    if quantize:
        p, t = quantize_8bit(p), quantize_8bit(t)
    import kornia

    if padding == "valid":
        smap = kornia.metrics.ssim(p, t, window_size=ws, max_val=1.0, padding="valid")  # [N, 3, h, w]
    else:
        smap = gaussian_ssim_map(p, t, ws, float(sigma), padding="zero")  # [N, 3, H, W]
    arr = smap.mean(dim=(1, 2, 3)).numpy().astype(np.float64)
    return ImageScores(per_image=arr, mean=float(arr.mean()))


def _ssim_from_moments(mu_p: torch.Tensor, mu_t: torch.Tensor, e_pp: torch.Tensor, e_tt: torch.Tensor, e_pt: torch.Tensor) -> torch.Tensor:
    """SSIM from the window-filtered moments E[p], E[t], E[p^2], E[t^2], E[pt] (C1 = 0.01^2, C2 = 0.03^2)."""
    s_pp = e_pp - mu_p ** 2
    s_tt = e_tt - mu_t ** 2
    s_pt = e_pt - mu_p * mu_t
    c1, c2 = 0.01 ** 2, 0.03 ** 2
    return ((2 * mu_p * mu_t + c1) * (2 * s_pt + c2)) / ((mu_p ** 2 + mu_t ** 2 + c1) * (s_pp + s_tt + c2))


def _gaussian_window_1d(window_size: int, sigma: float, like: torch.Tensor) -> torch.Tensor:
    g = torch.exp(-((torch.arange(window_size, dtype=like.dtype, device=like.device) - window_size // 2) ** 2) / (2 * sigma * sigma))
    return g / g.sum()


def gaussian_ssim_map(p: torch.Tensor, t: torch.Tensor, window_size: int = 11, sigma: float = 1.5, padding: str = "zero") -> torch.Tensor:
    """SSIM map with a Gaussian window, differentiable (also the Gaussian variants' training loss).

    The window is separable: the five moment maps are stacked and filtered by one vertical and one
    horizontal 1-D convolution (2 x 11 taps instead of 121; with zero padding the same sums as the 2-D
    window, to float rounding). :func:`gaussian_ssim_map_reference` (one 2-D convolution per moment) is
    its twin in the tests.

    Args:
        p, t: (N, C, H, W) float images in [0, 1].
        padding: ``"zero"`` (FSGS / 3DGS ``utils/loss_utils.py``: moments filtered with zero padding,
            full (H, W) map) or ``"valid"`` (only where the window fits: (H - ws + 1, W - ws + 1)).

    Returns:
        (N, C, H', W') SSIM map (C1 = 0.01^2, C2 = 0.03^2).
    """
    import torch.nn.functional as F

    g = _gaussian_window_1d(window_size, sigma, p)
    C = p.shape[1]
    pad = window_size // 2 if padding == "zero" else 0
    x = torch.cat([p, t, p * p, t * t, p * t], 1)  # (N, 5C, H, W)
    kv = g.view(1, 1, window_size, 1).expand(5 * C, 1, window_size, 1).contiguous()
    kh = g.view(1, 1, 1, window_size).expand(5 * C, 1, 1, window_size).contiguous()
    y = F.conv2d(F.conv2d(x, kv, padding=(pad, 0), groups=5 * C), kh, padding=(0, pad), groups=5 * C)
    return _ssim_from_moments(*y.split(C, 1))


def gaussian_ssim_map_reference(p: torch.Tensor, t: torch.Tensor, window_size: int = 11, sigma: float = 1.5,
                                padding: str = "zero") -> torch.Tensor:
    """:func:`gaussian_ssim_map` with one 2-D (window x window) convolution per moment (the slow twin)."""
    import torch.nn.functional as F

    g = _gaussian_window_1d(window_size, sigma, p)
    C = p.shape[1]
    k = (g[:, None] * g[None, :])[None, None].expand(C, 1, window_size, window_size).contiguous()
    pad = window_size // 2 if padding == "zero" else 0

    def f(x: torch.Tensor) -> torch.Tensor:
        return F.conv2d(x, k, padding=pad, groups=C)

    return _ssim_from_moments(f(p), f(t), f(p * p), f(t * t), f(p * t))
