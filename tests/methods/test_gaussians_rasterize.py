"""The CPU Gaussian rasteriser: fast path vs the slow reference twin, gradcheck (float64), hard cases."""

from __future__ import annotations

import math

import pytest
import torch

from methods.gaussians.rasterize import project_gaussians, quat_to_rotmat, rasterize_gaussians
from methods.gaussians.rasterize_reference import rasterize_gaussians_reference

F64 = torch.float64


def _K(W: int, H: int, f: float = 20.0, dtype=F64) -> torch.Tensor:
    return torch.tensor([[f, 0, (W - 1) / 2], [0, f, (H - 1) / 2], [0, 0, 1.0]], dtype=dtype)


def _scene(n: int, seed: int = 0, dtype=F64, W: int = 16, H: int = 12, z: float = 3.0, spread: float = 0.4, smax: float = 0.2):
    g = torch.Generator().manual_seed(seed)
    means = torch.randn(n, 3, generator=g, dtype=dtype) * spread + torch.tensor([0, 0, z], dtype=dtype)
    quats = torch.randn(n, 4, generator=g, dtype=dtype)
    scales = torch.rand(n, 3, generator=g, dtype=dtype) * smax + 0.02
    opac = torch.rand(n, generator=g, dtype=dtype) * 0.8 + 0.1
    cols = torch.rand(n, 3, generator=g, dtype=dtype)
    return means, quats, scales, opac, cols, torch.eye(4, dtype=dtype), _K(W, H, dtype=dtype), W, H


def _close(a, b, tol=1e-10):
    for k in ("color", "depth", "alpha"):
        assert torch.allclose(a[k], b[k], atol=tol, rtol=0), (k, (a[k] - b[k]).abs().max())


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_fast_matches_reference(seed):
    args = _scene(25, seed)
    bg = torch.tensor([0.2, 0.5, 0.7], dtype=F64)
    _close(rasterize_gaussians(*args, background=bg), rasterize_gaussians_reference(*args, background=bg))


def test_row_bands_do_not_change_the_result():
    args = _scene(40, 3, W=20, H=15)
    _close(rasterize_gaussians(*args, max_pairs=50), rasterize_gaussians(*args))


def test_rotated_camera_matches_reference():
    args = list(_scene(20, 4))
    R = quat_to_rotmat(torch.tensor([0.98, 0.1, -0.15, 0.05], dtype=F64))
    vm = torch.eye(4, dtype=F64)
    vm[:3, :3] = R
    vm[:3, 3] = torch.tensor([0.1, -0.2, 0.3], dtype=F64)
    args[5] = vm
    _close(rasterize_gaussians(*args), rasterize_gaussians_reference(*args))


def test_single_gaussian_analytic_centre():
    """Centre pixel of one opaque-ish Gaussian: alpha = opacity, colour = opacity * c + (1 - opacity) * bg."""
    W, H = 9, 9
    means = torch.tensor([[0.0, 0.0, 2.0]], dtype=F64)
    out = rasterize_gaussians(means, torch.tensor([[1.0, 0, 0, 0]], dtype=F64), torch.full((1, 3), 0.05, dtype=F64),
                              torch.tensor([0.6], dtype=F64), torch.tensor([[1.0, 0.0, 0.0]], dtype=F64), torch.eye(4, dtype=F64),
                              _K(W, H), W, H, background=torch.tensor([0.0, 0.0, 1.0], dtype=F64))
    assert out["alpha"][4, 4].item() == pytest.approx(0.6)
    assert out["depth"][4, 4].item() == pytest.approx(0.6 * 2.0)
    assert out["color"][4, 4].tolist() == pytest.approx([0.6, 0.0, 0.4])
    # symmetric footprint
    assert out["alpha"][4, 3].item() == pytest.approx(out["alpha"][4, 5].item())


def test_projection_conic_is_inverse_covariance():
    means, quats, scales, *_ = _scene(5, 5)
    p = project_gaussians(means, quats, scales, torch.eye(4, dtype=F64), _K(16, 12), 16, 12)
    A, B, C = p.conics.unbind(-1)
    assert torch.all(A * C - B * B > 0) and torch.all(A > 0)


def test_gradcheck_float64():
    means, quats, scales, opac, cols, vm, K, W, H = _scene(4, 7, W=8, H=6, spread=0.15, smax=0.1)
    bg = torch.tensor([0.1, 0.2, 0.3], dtype=F64)

    def f(m, q, s, o, c):
        out = rasterize_gaussians(m, q, s, o, c, vm, K, W, H, background=bg)
        return out["color"], out["depth"], out["alpha"]

    inputs = tuple(t.clone().requires_grad_() for t in (means, quats, scales, opac, cols))
    assert torch.autograd.gradcheck(f, inputs, eps=1e-6, atol=1e-5, rtol=1e-4)


def test_gradients_match_reference():
    args = _scene(12, 8)
    ins = [t.clone().requires_grad_() for t in args[:5]]
    ins2 = [t.clone().requires_grad_() for t in args[:5]]
    w = torch.rand(args[8], args[7], 3, dtype=F64, generator=torch.Generator().manual_seed(0))
    a = rasterize_gaussians(*ins, *args[5:])
    b = rasterize_gaussians_reference(*ins2, *args[5:])
    ((a["color"] * w).sum() + a["depth"].sum() + a["alpha"].sum()).backward()
    ((b["color"] * w).sum() + b["depth"].sum() + b["alpha"].sum()).backward()
    for x, y in zip(ins, ins2):
        assert torch.allclose(x.grad, y.grad, atol=1e-9), (x.grad - y.grad).abs().max()


# ------------------------------------------------------------------ hard cases
def _finite_everything(out, params):
    for k in ("color", "depth", "alpha"):
        assert torch.isfinite(out[k]).all(), k
    loss = out["color"].sum() + out["depth"].sum() + out["alpha"].sum()
    loss.backward()
    for p in params:
        assert p.grad is None or torch.isfinite(p.grad).all()


@pytest.mark.parametrize("dtype", [torch.float32, F64])
def test_zero_and_huge_scales(dtype):
    means, quats, scales, opac, cols, vm, K, W, H = _scene(6, 9, dtype=dtype)
    scales = scales.clone()
    scales[0] = 0.0
    scales[1] = 1e8
    scales[2, 0] = 1e30
    params = [t.clone().requires_grad_() for t in (means, quats, scales, opac, cols)]
    out = rasterize_gaussians(*params, vm, K, W, H)
    _finite_everything(out, params)
    assert out["alpha"].min() > 0  # the huge Gaussians cover every pixel


def test_zero_quaternion_is_identity():
    R = quat_to_rotmat(torch.zeros(1, 4, dtype=F64))
    assert torch.allclose(R[0], torch.eye(3, dtype=F64))


def test_behind_camera_and_near_plane_culled():
    W, H = 8, 6
    means = torch.tensor([[0.0, 0.0, -2.0], [0.0, 0.0, 0.01], [0.0, 0.0, 0.0], [0.0, 0.0, 1e-7]], dtype=F64, requires_grad=True)
    n = means.shape[0]
    quats = torch.tensor([[1.0, 0, 0, 0]] * n, dtype=F64, requires_grad=True)
    scales = torch.full((n, 3), 0.5, dtype=F64, requires_grad=True)
    opac = torch.full((n,), 0.9, dtype=F64, requires_grad=True)
    cols = torch.ones(n, 3, dtype=F64, requires_grad=True)
    out = rasterize_gaussians(means, quats, scales, opac, cols, torch.eye(4, dtype=F64), _K(W, H), W, H, near=0.01)
    assert out["proj"].ids.numel() == 0 and out["n_pairs"] == 0
    assert torch.all(out["alpha"] == 0)
    _finite_everything(out, [means, quats, scales, opac, cols])


def test_just_in_front_of_near_plane_is_finite():
    W, H = 8, 6
    means = torch.tensor([[0.3, -0.2, 0.0100001], [5.0, 5.0, 0.02]], dtype=torch.float32, requires_grad=True)
    quats = torch.tensor([[1.0, 0, 0, 0]] * 2, requires_grad=True)
    scales = torch.full((2, 3), 0.01, requires_grad=True)
    opac = torch.full((2,), 0.5, requires_grad=True)
    cols = torch.ones(2, 3, requires_grad=True)
    out = rasterize_gaussians(means, quats, scales, opac, cols, torch.eye(4), _K(W, H, dtype=torch.float32), W, H, near=0.01)
    _finite_everything(out, [means, quats, scales, opac, cols])


def test_fully_transparent_scene():
    means, quats, scales, _, cols, vm, K, W, H = _scene(10, 10)
    opac = torch.zeros(10, dtype=F64, requires_grad=True)
    bg = torch.tensor([0.3, 0.3, 0.3], dtype=F64)
    out = rasterize_gaussians(means, quats, scales, opac, cols, vm, K, W, H, background=bg)
    assert out["n_pairs"] == 0
    assert torch.allclose(out["color"], bg.expand(H, W, 3)) and torch.all(out["depth"] == 0)
    out["color"].sum().backward()  # still part of the graph
    assert torch.all(opac.grad == 0)


def test_empty_input():
    z = torch.zeros(0, 3)
    out = rasterize_gaussians(z, torch.zeros(0, 4), z, torch.zeros(0), z, torch.eye(4), _K(4, 4, dtype=torch.float32), 4, 4)
    assert out["color"].shape == (4, 4, 3) and torch.all(out["alpha"] == 0)


@pytest.mark.slow
def test_thousands_of_gaussians_on_one_pixel():
    """5000 Gaussians stacked on the centre pixel: the cut-off stops at T < 1e-4, matching the reference."""
    n, W, H = 5000, 5, 5
    g = torch.Generator().manual_seed(0)
    means = torch.zeros(n, 3, dtype=F64)
    means[:, 2] = 2.0 + torch.rand(n, generator=g, dtype=F64)
    quats = torch.tensor([[1.0, 0, 0, 0]], dtype=F64).repeat(n, 1)
    scales = torch.full((n, 3), 0.01, dtype=F64)
    opac = torch.full((n,), 0.01, dtype=F64)
    cols = torch.rand(n, 3, generator=g, dtype=F64)
    args = (means, quats, scales, opac, cols, torch.eye(4, dtype=F64), _K(W, H), W, H)
    out = rasterize_gaussians(*args)
    ref = rasterize_gaussians_reference(*args)
    _close(out, ref, tol=1e-9)
    # T after k Gaussians = 0.99^k; the last included k has 0.99^k >= 1e-4 -> k = 916
    k = math.floor(math.log(1e-4) / math.log(0.99))
    assert out["alpha"][2, 2].item() == pytest.approx(1 - 0.99 ** k, abs=1e-9)
    p = [t.clone().requires_grad_() for t in args[:5]]
    _finite_everything(rasterize_gaussians(*p, *args[5:]), p)


def test_float32_close_to_float64():
    args = _scene(30, 11, W=24, H=18)
    a64 = rasterize_gaussians(*args)
    a32 = rasterize_gaussians(*[t.float() if torch.is_tensor(t) else t for t in args])
    for k in ("color", "depth", "alpha"):
        assert torch.allclose(a32[k].double(), a64[k], atol=1e-4), k


def test_bad_shapes_raise():
    args = list(_scene(3, 0))
    args[1] = args[1][:, :3]
    with pytest.raises(ValueError, match="quats"):
        rasterize_gaussians(*args)
