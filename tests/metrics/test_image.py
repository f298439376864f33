import numpy as np
import pytest
import torch
from skimage.metrics import peak_signal_noise_ratio, structural_similarity

from metrics.image import psnr, quantize_8bit, ssim


def pair(seed=0, n=3, h=40, w=52):
    rng = np.random.default_rng(seed)
    a = rng.random((n, h, w, 3))
    b = np.clip(a + rng.normal(0, 0.08, a.shape), 0, 1)
    q = lambda x: np.round(np.clip(x, 0, 1) * 255) / 255
    return a, b, q(a), q(b)


def test_against_scikit_image():
    a, b, qa, qb = pair()
    ps, ss = psnr(b, a), ssim(b, a)
    for i in range(a.shape[0]):
        ref_p = peak_signal_noise_ratio(qa[i], qb[i], data_range=1.0)
        ref_s = structural_similarity(qa[i], qb[i], data_range=1.0, channel_axis=-1, gaussian_weights=True, sigma=1.5, use_sample_covariance=False)
        assert ps.per_image[i] == pytest.approx(ref_p, abs=1e-4)
        assert ss.per_image[i] == pytest.approx(ref_s, abs=1e-4)
    assert ps.mean == pytest.approx(ps.per_image.mean()) and ss.mean == pytest.approx(ss.per_image.mean())


def test_quantisation_is_applied():
    a = np.full((16, 16, 3), 0.5)
    b = a + 0.001  # same 8-bit value (127.5 -> 128, 127.755 -> 128)
    assert psnr(b, a).mean == 100.0
    assert psnr(b, a, quantize=False).mean == pytest.approx(60.0)
    x = torch.tensor([-0.2, 0.0, 0.5, 1.3])
    assert torch.equal(quantize_8bit(x), torch.tensor([0.0, 0.0, 128 / 255, 1.0]))


def test_identical_and_constant_images():
    a, _, _, _ = pair(1, n=2)
    assert psnr(a, a).per_image.tolist() == [100.0, 100.0]
    assert psnr(a, a, max_db=80.0).mean == 80.0
    assert ssim(a, a).mean == pytest.approx(1.0)
    c0, c1 = np.full((20, 20, 3), 0.2), np.full((20, 20, 3), 0.6)
    assert ssim(c0, c0).mean == pytest.approx(1.0)
    s = ssim(c0, c1).mean
    assert np.isfinite(s) and 0 < s < 1
    mse = (np.round(0.6 * 255) / 255 - np.round(0.2 * 255) / 255) ** 2
    assert psnr(c0, c1).mean == pytest.approx(-10 * np.log10(mse))


def test_single_image_torch_float32():
    a, b, _, _ = pair(2, n=1)
    r64 = ssim(b[0], a[0]).mean
    r32 = ssim(torch.from_numpy(b[0]).float(), torch.from_numpy(a[0]).float()).mean
    assert r32 == pytest.approx(r64, abs=1e-6)


def test_errors():
    a = np.zeros((8, 8, 3))
    with pytest.raises(ValueError, match="shapes differ"):
        psnr(a, np.zeros((8, 9, 3)))
    with pytest.raises(ValueError, match="shape"):
        psnr(np.zeros((8, 8)), np.zeros((8, 8)))
    with pytest.raises(TypeError):
        psnr(np.zeros((8, 8, 3), dtype=np.uint8), a)
    with pytest.raises(ValueError, match="at least"):
        ssim(a, a)
    with pytest.raises(ValueError, match="NaN"):
        psnr(np.full((8, 8, 3), np.nan), a)


def _fsgs_ssim_reference(x: np.ndarray, y: np.ndarray) -> float:
    """The slow twin: FSGS's utils/loss_utils.py ``_ssim`` written out (a full 11 x 11 Gaussian window, one
    ``F.conv2d`` with ``padding=5`` of zeros per moment, mean over the whole map), on 8-bit-quantised images."""
    q = lambda a: torch.from_numpy(np.round(np.clip(a, 0, 1) * 255) / 255).permute(2, 0, 1)[None]
    a, b = q(x), q(y)
    g = torch.exp(-((torch.arange(11, dtype=torch.float64) - 5) ** 2) / (2 * 1.5 ** 2))
    g = g / g.sum()
    w = (g[:, None] @ g[None, :])[None, None].expand(3, 1, 11, 11).contiguous()
    conv = lambda im: torch.nn.functional.conv2d(im, w, padding=5, groups=3)
    mu1, mu2 = conv(a), conv(b)
    s11, s22, s12 = conv(a * a) - mu1 ** 2, conv(b * b) - mu2 ** 2, conv(a * b) - mu1 * mu2
    c1, c2 = 0.01 ** 2, 0.03 ** 2
    m = ((2 * mu1 * mu2 + c1) * (2 * s12 + c2)) / ((mu1 ** 2 + mu2 ** 2 + c1) * (s11 + s22 + c2))
    return float(m.mean())


def test_zero_padded_ssim_matches_fsgs_and_differs_from_valid():
    a, b, _, _ = pair(3, n=2, h=48, w=64)
    zero = ssim(b, a, padding="zero")
    for i in range(2):
        assert zero.per_image[i] == pytest.approx(_fsgs_ssim_reference(b[i], a[i]), abs=1e-10)
    # the conventions differ at the border (small images: a large border fraction)
    valid = ssim(b, a)
    assert abs(zero.mean - valid.mean) > 1e-3
    assert ssim(a, a, padding="zero").mean == pytest.approx(1.0)
    with pytest.raises(ValueError, match="padding"):
        ssim(a, a, padding="reflect")


@pytest.mark.parametrize("padding", ["zero", "valid"])
def test_separable_ssim_map_matches_the_2d_window_twin_with_gradients(padding):
    """The separable SSIM map (the metric and the Gaussian variants' loss) against one 2-D convolution per
    moment: values and the gradient of the mean (float32 and float64)."""
    from metrics.image import gaussian_ssim_map, gaussian_ssim_map_reference

    g = torch.Generator().manual_seed(3)
    for dtype, tol in ((torch.float32, 2e-5), (torch.float64, 1e-12)):
        p = torch.rand(2, 3, 40, 53, generator=g, dtype=dtype).requires_grad_(True)
        t = (p.detach() + 0.1 * torch.randn(p.shape, generator=g, dtype=dtype)).clamp(0, 1)
        a = gaussian_ssim_map(p, t, padding=padding)
        (ga,) = torch.autograd.grad(a.mean(), p)
        b = gaussian_ssim_map_reference(p, t, padding=padding)
        (gb,) = torch.autograd.grad(b.mean(), p)
        assert a.shape == b.shape
        assert (a - b).abs().max().item() < tol
        assert (ga - gb).abs().max().item() < tol * gb.abs().max().item() * 10
