"""The C++ rasteriser (``kernel="cpp"``, the default for float32) against its twin, the PyTorch path
(``kernel="torch"``): values, every input gradient and the screen-space gradient densification reads, on
random scenes and on the hard cases (cut-off, clamped alpha, ties in depth, boxes off the image)."""

from __future__ import annotations

import math

import pytest
import torch

from methods.gaussians.raster_kernel import raster_kernel_available
from methods.gaussians.rasterize import project_gaussians, quat_to_rotmat, rasterize_gaussians

pytestmark = pytest.mark.skipif(not raster_kernel_available(), reason="no C++ compiler")
F32 = torch.float32


def _K(W: int, H: int, f: float) -> torch.Tensor:
    return torch.tensor([[f, 0, (W - 1) / 2], [0, f, (H - 1) / 2], [0, 0, 1.0]], dtype=F32)


def _scene(n: int, seed: int, W: int, H: int, f: float = 40.0, spread=(0.8, 0.6, 0.4), smin: float = 0.005, smax: float = 0.05):
    g = torch.Generator().manual_seed(seed)
    means = torch.randn(n, 3, generator=g) * torch.tensor(spread) + torch.tensor([0.0, 0.0, 3.0])
    quats = torch.randn(n, 4, generator=g)
    scales = torch.rand(n, 3, generator=g) * (smax - smin) + smin
    opac = torch.rand(n, generator=g) * 0.9 + 0.05
    cols = torch.rand(n, 3, generator=g)
    return [means, quats, scales, opac, cols], torch.eye(4), _K(W, H, f), W, H


def _render_and_grads(params, vm, K, W, H, kernel: str, bg=None):
    p = [t.clone().requires_grad_(True) for t in params]
    out = rasterize_gaussians(*p, vm, K, W, H, background=bg, kernel=kernel)
    out["proj"].means2d.retain_grad()
    wc = torch.linspace(0.2, 1.0, out["color"].shape[-1])
    loss = (out["color"] * wc).sum() + 0.3 * out["depth"].sum() + 0.7 * (out["alpha"] ** 2).sum()
    loss.backward()
    grads = [t.grad for t in p] + [out["proj"].means2d.grad]
    return out, grads


def _assert_twins(params, vm, K, W, H, bg=None, vtol: float = 2e-6, gtol: float = 2e-5):
    a, ga = _render_and_grads(params, vm, K, W, H, "torch", bg)
    b, gb = _render_and_grads(params, vm, K, W, H, "cpp", bg)
    assert a["n_pairs"] == b["n_pairs"] and a["n_candidates"] == b["n_candidates"]
    for k in ("color", "depth", "alpha"):
        scale = max(1.0, a[k].abs().max().item())
        assert torch.allclose(a[k], b[k], atol=vtol * scale, rtol=0), (k, (a[k] - b[k]).abs().max())
    for name, x, y in zip(("means", "quats", "scales", "opacities", "colors", "means2d"), ga, gb):
        assert x is not None and y is not None, name
        assert torch.isfinite(y).all(), name
        scale = max(1e-3, x.abs().max().item())
        assert (x - y).abs().max().item() <= gtol * scale, (name, (x - y).abs().max().item(), scale)
    return a, b


@pytest.mark.parametrize("seed,n,W,H", [(0, 300, 32, 24), (1, 2000, 64, 48), (2, 50, 17, 13)])
def test_cpp_kernel_matches_the_torch_path(seed, n, W, H):
    params, vm, K, W, H = _scene(n, seed, W, H)
    a, _ = _assert_twins(params, vm, K, W, H, bg=torch.tensor([0.2, 0.5, 0.7]))
    assert a["n_pairs"] > 10 * n ** 0.5  # the scene has real overlap, not a handful of pairs


def test_cpp_kernel_matches_when_alpha_clamps_and_the_cut_off_binds():
    """Opaque, large Gaussians: alpha clamps at 0.99 and pixels stop at T < 1e-4 after a few pairs."""
    params, vm, K, W, H = _scene(400, 3, 24, 18, smin=0.1, smax=0.3)
    params[3] = torch.full_like(params[3], 1.0)
    a, b = _assert_twins(params, vm, K, W, H)
    assert b["n_pairs"] < 0.5 * b["n_candidates"]  # the cut-off removed most candidates


def test_cpp_kernel_keeps_index_order_for_equal_depths():
    """Gaussians at exactly the same depth are composited by index (the twin's stable sort)."""
    n, W, H = 6, 9, 7
    means = torch.zeros(n, 3)
    means[:, 2] = 2.0
    means[:, 0] = torch.linspace(-0.05, 0.05, n)
    quats = torch.tensor([[1.0, 0, 0, 0]]).repeat(n, 1)
    scales = torch.full((n, 3), 0.1)
    opac = torch.full((n,), 0.6)
    cols = torch.eye(3).repeat(2, 1)
    _assert_twins([means, quats, scales, opac, cols], torch.eye(4), _K(W, H, 20.0), W, H)


def test_cpp_kernel_boxes_partly_and_wholly_off_the_image():
    params, vm, K, W, H = _scene(500, 4, 20, 16, spread=(3.0, 3.0, 0.5), smax=0.2)
    _assert_twins(params, vm, K, W, H)


def test_cpp_kernel_with_gaussians_behind_the_camera():
    """Some Gaussians culled (z <= near): the visible subset is gathered and the gradients scattered back."""
    params, vm, K, W, H = _scene(300, 9, 20, 16)
    params[0][::7, 2] = -1.0
    a, b = _assert_twins(params, vm, K, W, H)
    assert 0 < b["proj"].ids.numel() < 300


def test_cpp_kernel_thousands_of_gaussians_on_one_pixel():
    """5000 Gaussians of opacity 0.01 stacked on the centre pixel: the cut-off after k = 916 pairs."""
    n, W, H = 5000, 5, 5
    g = torch.Generator().manual_seed(0)
    means = torch.zeros(n, 3)
    means[:, 2] = 2.0 + torch.rand(n, generator=g)
    quats = torch.tensor([[1.0, 0, 0, 0]]).repeat(n, 1)
    scales = torch.full((n, 3), 0.01)
    opac = torch.full((n,), 0.01)
    cols = torch.rand(n, 3, generator=g)
    a, b = _assert_twins([means, quats, scales, opac, cols], torch.eye(4), _K(W, H, 20.0), W, H)
    k = math.floor(math.log(1e-4) / math.log(0.99))
    assert b["alpha"][2, 2].item() == pytest.approx(1 - 0.99 ** k, abs=1e-5)


def test_cpp_kernel_no_gradient_mode_and_single_channel():
    params, vm, K, W, H = _scene(200, 5, 16, 12)
    params[4] = params[4][:, :1]
    with torch.no_grad():
        a = rasterize_gaussians(*params, vm, K, W, H, kernel="torch")
        b = rasterize_gaussians(*params, vm, K, W, H, kernel="cpp")
    assert b["color"].shape == (H, W, 1)
    assert torch.allclose(a["color"], b["color"], atol=2e-6)


def test_unknown_kernel_raises():
    params, vm, K, W, H = _scene(3, 6, 8, 6)
    with pytest.raises(ValueError, match="kernel"):
        rasterize_gaussians(*params, vm, K, W, H, kernel="cuda")


def _rotated_viewmat() -> torch.Tensor:
    vm = torch.eye(4)
    vm[:3, :3] = quat_to_rotmat(torch.tensor([0.9, 0.2, -0.3, 0.1]))
    vm[:3, 3] = torch.tensor([0.1, -0.2, 0.3])
    return vm


def test_cpp_projection_matches_the_torch_projection_with_gradients():
    """Rotated camera; Gaussians past the slope clamp (off to the side), a zero quaternion, zero and clamped
    (> max_scale) scales: values and the gradients of a random functional of every output."""
    params, _, K, W, H = _scene(400, 7, 24, 18, spread=(2.5, 2.0, 0.6), smax=0.3)
    params[1][0] = 0.0  # zero quaternion: the identity rotation, no gradient
    params[2][1] = 0.0  # zero scales
    params[2][2, 1] = 50.0  # above max_scale: clamped, no gradient on that axis
    vm = _rotated_viewmat()
    g = torch.Generator().manual_seed(1)
    outs = {}
    for kernel in ("torch", "cpp"):
        p = [t.clone().requires_grad_(True) for t in params[:3]]
        proj = project_gaussians(*p, vm, K, W, H, max_scale=10.0, kernel=kernel)
        g.manual_seed(1)
        loss = sum((t * torch.randn(t.shape, generator=g)).sum() for t in (proj.means2d, proj.conics, proj.depths))
        loss.backward()
        outs[kernel] = (proj, [t.grad for t in p])
    (pa, ga), (pb, gb) = outs["torch"], outs["cpp"]
    assert torch.equal(pa.ids, pb.ids) and pa.ids.numel() > 300
    for name in ("means2d", "conics", "depths", "extents", "radii"):
        x, y = getattr(pa, name), getattr(pb, name)
        assert x.dtype == y.dtype and torch.allclose(x, y, rtol=1e-6, atol=1e-6), (name, (x - y).abs().max())
    for name, x, y in zip(("means", "quats", "scales"), ga, gb):
        assert torch.allclose(x, y, rtol=1e-4, atol=1e-4 * x.abs().max().item()), (name, (x - y).abs().max(), x.abs().max())
    assert gb[1][0].abs().max() == 0 and gb[2][2, 1] == 0
    assert all(torch.isfinite(x).all() for x in gb)  # (a zero scale's gradient is 0: the covariance is quadratic in it)


def test_cpp_path_with_a_rotated_camera_matches():
    params, _, K, W, H = _scene(600, 8, 32, 24, spread=(1.5, 1.0, 0.5))
    _assert_twins(params, _rotated_viewmat(), K, W, H, bg=torch.tensor([0.3, 0.3, 0.3]))


def test_cpp_kernel_in_row_bands_matches():
    """A small candidate budget splits the image into many row bands (bounded memory): same result."""
    params, vm, K, W, H = _scene(400, 10, 24, 18)
    full = rasterize_gaussians(*params, vm, K, W, H, kernel="cpp")
    banded = rasterize_gaussians(*params, vm, K, W, H, kernel="cpp", max_pairs=50)
    for k in ("color", "depth", "alpha"):
        assert torch.equal(full[k], banded[k]), k
    assert full["n_pairs"] == banded["n_pairs"] and full["n_candidates"] == banded["n_candidates"]
    p = [t.clone().requires_grad_(True) for t in params]
    rasterize_gaussians(*p, vm, K, W, H, kernel="cpp", max_pairs=50)["color"].sum().backward()
    q = [t.clone().requires_grad_(True) for t in params]
    rasterize_gaussians(*q, vm, K, W, H, kernel="torch")["color"].sum().backward()
    for a, b in zip(p, q):
        assert torch.allclose(a.grad, b.grad, atol=2e-5 * max(1e-3, b.grad.abs().max().item()))


def test_single_channel_and_empty_image_gradients():
    params, vm, K, W, H = _scene(150, 11, 16, 12)
    params[4] = params[4][:, :1]
    _assert_twins(params, vm, K, W, H)
    off = [t.clone() for t in params]
    off[0][:, 0] += 50.0  # every box off the image: no pairs, zero gradients, background only
    a, b = _assert_twins(off, vm, K, W, H, bg=torch.tensor([0.4]))
    assert b["n_pairs"] == 0 and torch.all(b["color"] == 0.4)


def test_camera_gradients_take_the_torch_path_and_bad_t_min_raises():
    params, vm, K, W, H = _scene(100, 12, 16, 12)
    grads = []
    for kernel in ("torch", "cpp"):
        v = vm.clone().requires_grad_(True)
        rasterize_gaussians(*params, v, K, W, H, kernel=kernel)["color"].sum().backward()
        grads.append(v.grad)
    assert grads[1] is not None and torch.allclose(grads[0], grads[1])
    with pytest.raises(ValueError, match="t_min"):
        rasterize_gaussians(*params, vm, K, W, H, t_min=0.0)
