"""MonoSDF on CPU: fast paths against their slow twins, hard cases stay finite, checkpoints resume exactly."""

from __future__ import annotations

import contextlib
import copy
import dataclasses

import numpy as np
import pytest
import torch

from bench.data.errors import BenchInputError
from methods.monosdf.field import ColorNetwork, LaplaceDensity, SDFNetwork, linear_blocks, sdf_gradient_autograd
from methods.monosdf.grid import (
    FeatureGrid,
    fast_available,
    interpolate_fast,
    interpolate_reference,
    jacobian_contract,
    jacobian_contract_reference,
    make_grid_spec,
    per_point_grid_kernel,
    simd_kernel_compiled,
)
from methods.monosdf.losses import normal_loss, smoothness_loss, solve_scale_shift, ssi_depth_loss
from methods.monosdf.render import composite_weights, sample_pdf
from methods.registry import method_config, typed_method_config


def _spec():
    return make_grid_spec(levels=5, features_per_level=2, log2_table=12, base_resolution=4, max_resolution=40)


# ----------------------------------------------------------------------------- grid: fast vs reference
@pytest.mark.skipif(not fast_available(), reason="no C++ compiler")
@pytest.mark.parametrize("kernel", ["default", "per_point"])
def test_grid_kernel_matches_reference_values_jacobian_and_table_gradient(kernel):
    spec = _spec()
    assert any(spec.hashed) and not all(spec.hashed)  # both dense and hashed levels are exercised
    grid = FeatureGrid(spec, init_scale=0.5, seed=1)
    x = torch.cat([torch.rand(3000, 3) * 2 - 1, torch.tensor([[1.0, 1.0, 1.0], [-1.0, -1.0, -1.0], [1.3, -2.0, 0.0]])])
    f_ref, j_ref = interpolate_reference(grid.table, x, spec)
    with per_point_grid_kernel() if kernel == "per_point" else contextlib.nullcontext():
        f_fast, j_fast = interpolate_fast(grid.table, x, spec)
    torch.testing.assert_close(f_fast, f_ref, atol=1e-5, rtol=1e-5)
    torch.testing.assert_close(j_fast, j_ref, atol=1e-3, rtol=1e-4)
    gf, gj = torch.randn_like(f_ref), torch.randn_like(j_ref)
    g_ref = torch.autograd.grad((f_ref * gf).sum() + (j_ref * gj).sum(), grid.table)[0]
    with per_point_grid_kernel() if kernel == "per_point" else contextlib.nullcontext():
        g_fast = torch.autograd.grad((f_fast * gf).sum() + (j_fast * gj).sum(), grid.table)[0]
    torch.testing.assert_close(g_fast, g_ref, atol=1e-3, rtol=1e-4)


@pytest.mark.skipif(not simd_kernel_compiled(), reason="the AVX-512 grid kernels need a CPU with AVX-512F")
@pytest.mark.parametrize("features", [1, 2, 4])
@pytest.mark.parametrize("threads", [1, 2])
def test_simd_grid_kernels_match_the_per_point_kernels(features, threads):
    """The AVX-512 kernels against their per-point twin: features, Jacobian and the table gradient from the
    features alone, the Jacobian alone and both, on a point count that leaves a partial block of 16, with points
    outside the cube (clamped) and on its faces, for every templated feature count, at 1 and 2 threads."""
    spec = make_grid_spec(levels=5, features_per_level=features, log2_table=12, base_resolution=4, max_resolution=40)
    grid = FeatureGrid(spec, init_scale=0.5, seed=3)
    g = torch.Generator().manual_seed(4)
    x = torch.cat([torch.rand(1003, 3, generator=g) * 2.4 - 1.2, torch.tensor([[1.0, 1.0, 1.0], [-1.0, -1.0, -1.0], [0.0, 1.0, -1.0]])])
    gf = torch.randn(x.shape[0], spec.levels * features, generator=g)
    gj = torch.randn(x.shape[0], 3, spec.levels * features, generator=g)
    before = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        out = {}
        for kernel in ("simd", "per_point"):
            with per_point_grid_kernel() if kernel == "per_point" else contextlib.nullcontext():
                f, j = interpolate_fast(grid.table, x, spec)
                f_only, _ = interpolate_fast(grid.table, x, spec, with_jacobian=False)
                grads = [torch.autograd.grad(loss, grid.table, retain_graph=True)[0] for loss in
                         ((f * gf).sum(), (j * gj).sum(), (f * gf).sum() + (j * gj).sum())]
            out[kernel] = (f, j, f_only, *grads)
    finally:
        torch.set_num_threads(before)
    for a, b in zip(out["simd"], out["per_point"]):
        torch.testing.assert_close(a, b, atol=1e-5 * float(b.abs().max()), rtol=1e-5)


@pytest.mark.skipif(not fast_available(), reason="no C++ compiler")
def test_jacobian_contraction_kernel_matches_reference_value_and_gradients():
    jac = torch.randn(1000, 3, 16, requires_grad=True)
    g = torch.randn(1000, 16, requires_grad=True)
    w = torch.randn(1000, 3)
    ref = jacobian_contract_reference(jac, g)
    fast = jacobian_contract(jac, g)
    torch.testing.assert_close(fast, ref, atol=1e-5, rtol=1e-5)
    for a, b in zip(torch.autograd.grad((fast * w).sum(), [jac, g]), torch.autograd.grad((ref * w).sum(), [jac, g])):
        torch.testing.assert_close(a, b, atol=1e-5, rtol=1e-5)


def test_reference_jacobian_matches_finite_differences():
    spec = _spec()
    grid = FeatureGrid(spec, init_scale=0.5, seed=2)
    x = torch.rand(50, 3, dtype=torch.float64) * 1.6 - 0.8
    table = grid.table.detach().double()
    _, jac = interpolate_reference(table, x, spec)
    eps = 1e-6
    for d in range(3):
        dx = torch.zeros(3, dtype=torch.float64)
        dx[d] = eps
        fp, _ = interpolate_reference(table, x + dx, spec, with_jacobian=False)
        fm, _ = interpolate_reference(table, x - dx, spec, with_jacobian=False)
        torch.testing.assert_close(jac[:, d, :], (fp - fm) / (2 * eps), atol=1e-4, rtol=1e-4)


# ----------------------------------------------------------------------------- field gradient vs autograd
@pytest.mark.parametrize("fast,pe,levels,radius", [(True, 0, 5, 1.0), (False, 0, 5, 1.0), (True, 6, 5, 1.0), (False, 3, 5, 1.0),
                                                     (True, 6, 2, 1.0), (True, 6, 5, 4.0), (False, 3, 5, 4.0)])
def test_explicit_sdf_gradient_matches_autograd(fast, pe, levels, radius):
    net = SDFNetwork(_spec(), hidden=32, layers=2, geo_features=4, radius=radius, fast_grid=fast, seed=0, pe_frequencies=pe)
    net.set_active_levels(levels)
    with torch.no_grad():
        net.grid.table.normal_(0, 0.3)
        for lin in net.linears:
            lin.weight.normal_(0, 0.3)
    x = (torch.rand(500, 3) * 2 - 1) * 0.7
    _, _, grad = net(x)
    torch.testing.assert_close(grad, sdf_gradient_autograd(net, x), atol=1e-3, rtol=1e-3)


@pytest.mark.parametrize("fast,pe,radius", [(True, 6, 1.0), (False, 3, 1.0), (True, 0, 1.0), (True, 6, 4.0)])
def test_explicit_sdf_gradient_backpropagates_like_double_backward(fast, pe, radius):
    """The eikonal / normal losses backpropagate through the explicit gradient: its parameter gradients
    must equal autograd's double backward through the slow twin (grid table and every MLP weight), run in
    float64 (the answer, free of float32 rounding). Each loss term on its own, so that neither hides the
    other's error."""
    net = SDFNetwork(_spec(), hidden=32, layers=2, geo_features=4, radius=radius, fast_grid=fast, seed=0, pe_frequencies=pe)
    with torch.no_grad():
        net.grid.table.normal_(0, 0.3)
        for lin in net.linears:
            lin.weight.normal_(0, 0.3)
    x = (torch.rand(300, 3) * 2 - 1) * 0.7
    target = torch.nn.functional.normalize(torch.randn(300, 3), dim=-1)
    net64 = copy.deepcopy(net).double()

    def params_of(n: SDFNetwork) -> list[torch.Tensor]:
        return [n.grid.table] + [p for lin in n.linears for p in lin.parameters()]

    terms = {"eikonal": lambda g: ((g.norm(dim=-1) - 1) ** 2).mean(),
             "normal": lambda g: (g * target.to(g.dtype)).sum(-1).mean()}
    grad = net(x)[2]  # the explicit gradient, evaluated once for both terms
    twin = sdf_gradient_autograd(net64, x.double(), create_graph=True)  # autograd's double backward, slow path
    for name, loss_of in terms.items():
        explicit = torch.autograd.grad(loss_of(grad), params_of(net), allow_unused=True, retain_graph=True)
        reference = torch.autograd.grad(loss_of(twin), params_of(net64), allow_unused=True, retain_graph=True)
        for got, want in zip(explicit, reference):
            if want is None:
                assert got is None or float(got.abs().max()) == 0.0
                continue
            # float32 sums of terms up to ~1e3 (radius 4): the float32 twin itself is off the float64 answer
            # by up to 5e-5 of the tensor's largest entry, the C++ path (-ffast-math) likewise (AMD Zen 3,
            # AVX2); a term 0.1 % off would be off by 1e-3 of it.
            scale = float(want.abs().max())
            torch.testing.assert_close(got.double(), want, atol=2e-4 * scale, rtol=0.0, msg=lambda m: f"{name}: {m}")


@pytest.mark.parametrize("fast,skip,weight_norm", [(True, (2,), False), (False, (2,), True), (True, (1, 3), True), (True, (), False),
                                                  (True, (4,), False)])  # (4,): the last layer re-takes the encoding
def test_mlp_variant_gradient_and_its_backward_match_autograd(fast, skip, weight_norm):
    """MonoSDF's MLP variant (no grid: PE alone, skip layers re-concatenating the encoding / sqrt(2),
    weight norm): the explicit gradient equals autograd through the slow twin (which concatenates
    literally, as MonoSDF's ``ImplicitNetwork``), and so do the parameter gradients of a loss on it."""
    net = SDFNetwork(None, hidden=48, layers=4, geo_features=4, radius=1.0, fast_grid=fast, seed=0, pe_frequencies=6,
                     skip=skip, weight_norm=weight_norm)
    assert net.grid is None and not any(n.startswith("grid.") for n, _ in net.named_parameters())
    with torch.no_grad():
        for p in net.parameters():
            p.add_(torch.randn_like(p) * 0.2)
    x = (torch.rand(300, 3) * 2 - 1) * 0.7
    sdf, geo, grad = net(x)
    assert sdf.shape == (300,) and geo.shape == (300, 4) and torch.isfinite(grad).all()
    torch.testing.assert_close(grad, sdf_gradient_autograd(net, x), atol=1e-3, rtol=1e-3)
    target = torch.nn.functional.normalize(torch.randn(300, 3), dim=-1)

    def loss_of(g: torch.Tensor) -> torch.Tensor:
        return ((g.norm(dim=-1) - 1) ** 2).mean() + (g * target).sum(-1).mean()

    params = list(net.parameters())
    explicit = torch.autograd.grad(loss_of(net(x)[2]), params, allow_unused=True)
    reference = torch.autograd.grad(loss_of(sdf_gradient_autograd(net, x, create_graph=True)), params, allow_unused=True)
    for got, want in zip(explicit, reference):
        if want is None:
            assert got is None or float(got.abs().max()) == 0.0
            continue
        # float32 through 5 layers (in float64 the two agree to 1e-9 relative): tolerance scaled to the tensor
        torch.testing.assert_close(got, want, atol=2e-3 * float(want.abs().max()), rtol=1e-3)


@pytest.mark.parametrize("skip,weight_norm", [((), False), ((2,), True)])
def test_mlp_variant_geometric_init_is_a_sphere(skip, weight_norm):
    """IDR geometric init with the encoding's frequencies switched off in the first and every skip layer:
    the MLP variant starts as a sphere SDF of radius init_radius (inside_out: positive inside)."""
    net = SDFNetwork(None, hidden=128, layers=4, geo_features=4, radius=1.0, init_radius=0.6, inside_out=True, pe_frequencies=6,
                     skip=skip, weight_norm=weight_norm)
    d = torch.nn.functional.normalize(torch.randn(400, 3), dim=-1)
    sdf, _, grad = net(d * 0.3)  # IDR's init is a sphere only roughly (as the grid variant's: test below)
    assert abs(float(sdf.mean()) - (0.6 - 0.3)) < 0.1 and float(sdf.min()) > 0.0
    assert float(torch.nn.functional.cosine_similarity(grad, -d).mean()) > 0.9  # inside-out: the SDF falls outward
    assert float(net(d * 0.6)[0].mean()) < float(sdf.mean()) and float(net(d * 0.85)[0].mean()) < 0.1


def test_object_scene_layout_is_monosdfs_the_mlp_sees_x_and_only_the_grid_sees_x_over_r():
    """MonoSDF's ImplicitNetworkGrid: PE and MLP on x (normalised units), the grid on x / divide_factor (= R
    here), the MLP output is the SDF. With a bounding sphere of R = 4 (DTU-like objects) the init sphere
    has init_radius in normalised units, and the SDF equals a hand-written forward pass of that layout."""
    net = SDFNetwork(_spec(), hidden=128, layers=2, geo_features=4, radius=4.0, init_radius=0.6, inside_out=False,
                     pe_frequencies=6, seed=0)
    d = torch.nn.functional.normalize(torch.randn(400, 3), dim=-1)
    assert abs(float(net(d * 0.6)[0].mean())) < 0.1  # the zero level set near |x| = 0.6, not 0.6 x R
    assert float(net(d * 0.2)[0].max()) < 0.0 < float(net(d * 1.2)[0].min())  # outward: negative inside
    with torch.no_grad():
        net.grid.table.normal_(0, 0.3)
        for lin in net.linears:
            lin.weight.normal_(0, 0.3)
        x = (torch.rand(200, 3) * 2 - 1) * 2.0
        from methods.monosdf.grid import interpolate_reference

        feat, _ = interpolate_reference(net.grid.table, x / 4.0, net.grid.spec, with_jacobian=False)
        f = 2.0 ** torch.arange(6, dtype=torch.float32)
        pe = torch.cat([x, torch.sin(x[:, None, :] * f[None, :, None]).reshape(200, -1),
                        torch.cos(x[:, None, :] * f[None, :, None]).reshape(200, -1)], dim=-1)
        a = torch.nn.functional.softplus(net.linears[0](torch.cat([feat, pe], dim=-1)), beta=100.0)
        a = torch.nn.functional.softplus(net.linears[1](a), beta=100.0)
        want = torch.minimum(net.linears[2](a)[:, 0], 4.0 - x.norm(dim=-1))
        torch.testing.assert_close(net(x, with_gradient=False)[0], want, atol=1e-4, rtol=1e-4)


def test_mlp_variant_rejects_a_skip_it_cannot_build():
    with pytest.raises(ValueError, match="skip"):
        SDFNetwork(None, hidden=32, layers=4, pe_frequencies=6, skip=(2,))  # 32 <= the encoding's 39 inputs
    with pytest.raises(ValueError, match="skip"):
        SDFNetwork(None, hidden=64, layers=2, pe_frequencies=6, skip=(3,))  # 3 linear layers: 1..2


@pytest.mark.skipif(not fast_available(), reason="no C++ compiler")
def test_encoding_kernels_match_reference_values_and_gradient():
    """The C++ positional encoding and its gradient chain against their PyTorch twins (values, and the
    chain's gradient with respect to its gradient input, which the eikonal / normal losses use)."""
    net = SDFNetwork(_spec(), hidden=32, layers=2, geo_features=4, radius=1.0, fast_grid=True, seed=0, pe_frequencies=6)
    u = torch.cat([torch.rand(2000, 3) * 2 - 1, torch.tensor([[1.0, -1.0, 0.0], [0.0, 0.0, 0.0]])])
    pe_fast, pe_ref = net.encode(u), net.encode_reference(u)
    assert pe_fast.shape == (u.shape[0], 3 + 6 * 6)
    torch.testing.assert_close(pe_fast, pe_ref, atol=2e-5, rtol=1e-5)  # sin / cos of arguments up to 32
    gin = torch.randn(u.shape[0], 39, requires_grad=True)
    w = torch.randn(u.shape[0], 3)
    fast, ref = net.pe_chain(gin, pe_ref), net.pe_chain_reference(gin, pe_ref)
    torch.testing.assert_close(fast, ref, atol=1e-4, rtol=1e-5)
    g_fast = torch.autograd.grad((fast * w).sum(), gin)[0]
    g_ref = torch.autograd.grad((ref * w).sum(), gin)[0]
    torch.testing.assert_close(g_fast, g_ref, atol=1e-5, rtol=1e-5)
    empty = torch.zeros(0, 3)  # e.g. a pruned pass with nothing left to evaluate
    assert net.encode(empty).shape == (0, 39) and net.pe_chain(torch.zeros(0, 39), net.encode(empty)).shape == (0, 3)
    sdf, _, grad = net(empty)
    assert sdf.shape == (0,) and grad.shape == (0, 3)


def test_linear_blocks_equals_linear_of_the_concatenation():
    lin = torch.nn.Linear(55, 32)
    a = torch.randn(400, 16, requires_grad=True)
    b = torch.randn(400, 39, requires_grad=True)
    w = torch.randn(400, 32)
    got = linear_blocks([a, b], lin.weight, lin.bias)
    want = lin(torch.cat([a, b], -1))
    torch.testing.assert_close(got, want, atol=1e-5, rtol=1e-5)
    params = [a, b, lin.weight, lin.bias]
    for x, y in zip(torch.autograd.grad((got * w).sum(), params), torch.autograd.grad((want * w).sum(), params)):
        torch.testing.assert_close(x, y, atol=1e-4, rtol=1e-5)
    with pytest.raises(ValueError, match="blocks give 16 inputs"):
        linear_blocks([a], lin.weight, lin.bias)
    # three blocks (two accumulate in place) on a per-point bias, which stays as it was
    bias = torch.randn(400, 32, requires_grad=True)
    before = bias.detach().clone()
    parts = [a[:, :5], a[:, 5:], b]
    got = linear_blocks(parts, lin.weight, bias)
    want = torch.cat([a, b], -1) @ lin.weight.t() + bias
    torch.testing.assert_close(got, want, atol=1e-5, rtol=1e-5)
    assert torch.equal(bias.detach(), before)
    params = [a, b, lin.weight, bias]
    for x, y in zip(torch.autograd.grad((got * w).sum(), params), torch.autograd.grad((want * w).sum(), params)):
        torch.testing.assert_close(x, y, atol=1e-4, rtol=1e-5)


@pytest.mark.parametrize("image", [3, None, "per_point"])
def test_colour_network_folds_the_image_code_like_the_concatenated_input(image):
    """The image code enters the colour network's first layer as a per-image bias; the twin feeds the
    concatenated ``[x, view, normal, geo, code]`` to the same MLP (values and every gradient)."""
    torch.manual_seed(0)
    net = ColorNetwork(geo_features=5, hidden=16, layers=1, appearance_dim=8, num_images=6)
    with torch.no_grad():
        net.codes.normal_(0, 0.5)
    P = 300
    x, v = torch.randn(P, 3), torch.randn(P, 3)
    n = torch.randn(P, 3, requires_grad=True)
    g = torch.randn(P, 5, requires_grad=True)
    img = torch.randint(0, 6, (P,)) if image == "per_point" else image
    w = torch.randn(P, 3)
    got, want = net(x, v, n, g, img), net.forward_reference(x, v, n, g, img)
    torch.testing.assert_close(got, want, atol=1e-6, rtol=1e-5)
    params = [n, g] + list(net.parameters())
    for a, b in zip(torch.autograd.grad((got * w).sum(), params), torch.autograd.grad((want * w).sum(), params)):
        torch.testing.assert_close(a, b, atol=1e-5, rtol=1e-4)


def test_a_lambertian_colour_network_ignores_the_view_direction():
    """``view_dependent=False``: the colour does not change with the view direction (fast path and twin);
    the default network's does."""
    torch.manual_seed(0)
    P = 200
    x, n, g = torch.randn(P, 3), torch.randn(P, 3), torch.randn(P, 5)
    v1, v2 = torch.randn(P, 3), torch.randn(P, 3)
    lambertian = ColorNetwork(geo_features=5, hidden=16, layers=1, appearance_dim=4, num_images=3, view_dependent=False)
    for forward in (lambertian, lambertian.forward_reference):
        torch.testing.assert_close(forward(x, v1, n, g, 1), forward(x, v2, n, g, 1))
    torch.testing.assert_close(lambertian(x, v1, n, g, 1), lambertian.forward_reference(x, v2, n, g, 1), atol=1e-6, rtol=1e-5)
    default = ColorNetwork(geo_features=5, hidden=16, layers=1, appearance_dim=4, num_images=3)
    assert (default(x, v1, n, g, 1) - default(x, v2, n, g, 1)).abs().max() > 1e-3


@pytest.mark.parametrize("pe", [0, 6])
def test_geometric_init_is_a_sphere_and_clamp_holds(pe):
    net = SDFNetwork(_spec(), hidden=64, layers=2, geo_features=4, radius=1.0, init_radius=0.6, inside_out=True, pe_frequencies=pe)
    x = torch.nn.functional.normalize(torch.randn(200, 3), dim=-1) * 0.3
    sdf, _, grad = net(x)
    vals = sdf.detach().numpy()  # inside-out: positive inside; with 64-wide layers IDR's init is a sphere only roughly
    assert abs(vals.mean() - (0.6 - 0.3)) < 0.1 and vals.min() > 0.0
    assert abs(float(grad.detach().norm(dim=-1).mean()) - 1) < 0.3
    far = torch.nn.functional.normalize(torch.randn(50, 3), dim=-1) * 0.999
    assert (net(far)[0] <= 1e-3 + 1e-6).all()  # clamped by R - |x|


# ----------------------------------------------------------------------------- hard cases
def test_density_is_finite_for_extreme_sdf_and_beta_at_min():
    dens = LaplaceDensity(beta_init=0.0, beta_min=1e-4)  # beta at beta_min
    s = torch.tensor([-1e30, -1e6, -1.0, -1e-6, 0.0, 1e-6, 1.0, 1e6, 1e30], requires_grad=True)
    sigma = dens(s)
    assert torch.isfinite(sigma).all() and (sigma >= 0).all()
    assert torch.isclose(sigma[4], torch.tensor(0.5 / 1e-4))
    sigma.sum().backward()
    assert torch.isfinite(s.grad).all() and torch.isfinite(dens.beta_param.grad)
    t = torch.linspace(0, 1, 9).expand(3, 9).contiguous()
    w = composite_weights(torch.tensor([[1e6] * 9, [-1e6] * 9, [0.5, 0.3, 0.1, -0.1, -0.3, -0.5, -0.7, -0.9, -1.1]]), t, dens)
    assert torch.isfinite(w).all() and (w.sum(-1) <= 1 + 1e-5).all()


def test_ssi_depth_loss_recovers_affine_and_handles_singular_cases():
    pred = torch.linspace(0.2, 1.0, 64, requires_grad=True)
    target = 3.0 * pred.detach() + 0.5
    assert ssi_depth_loss(pred, target, torch.ones(64)) < 1e-8
    s, t = solve_scale_shift(pred.detach(), target, torch.ones(64))
    assert abs(float(s) - 3.0) < 1e-4 and abs(float(t) - 0.5) < 1e-4
    cases = {
        "all-zero prior": (pred, torch.zeros(64)),
        "constant prior": (pred, torch.full((64,), 2.0)),
        "constant rendered depth": (torch.full((64,), 0.7, requires_grad=True), target),
    }
    for name, (p, q) in cases.items():
        loss = ssi_depth_loss(p, q, torch.ones(64))
        (g,) = torch.autograd.grad(loss, p, allow_unused=True)
        assert torch.isfinite(loss), name
        assert g is None or torch.isfinite(g).all(), name
    assert float(ssi_depth_loss(pred.detach(), torch.zeros(64), torch.ones(64))) == 0.0  # no valid ray: no loss


def test_negative_scale_fit_is_dropped_only_when_asked():
    """A rendered depth anti-correlated with the prior fits with a negative scale: MonoSDF keeps its
    (mirror-seeking) gradient, ``drop`` gives loss 0 and no gradient; a positive fit is unchanged."""
    from methods.monosdf.losses import ssi_depth_fit

    pred = torch.linspace(0.2, 1.0, 64, requires_grad=True)
    target = 2.0 - 1.5 * pred.detach() + 0.05 * torch.sin(20 * pred.detach())
    keep, s_keep = ssi_depth_fit(pred, target, torch.ones(64), "keep")
    drop, s_drop = ssi_depth_fit(pred, target, torch.ones(64), "drop")
    assert float(s_keep) < 0 and float(s_drop) < 0 and float(keep) > 0 and float(drop) == 0.0
    (g,) = torch.autograd.grad(drop, pred, allow_unused=True)
    assert g is None or float(g.abs().sum()) == 0.0
    pos = 0.5 + 1.5 * pred.detach() + 0.05 * torch.sin(20 * pred.detach())
    assert torch.equal(ssi_depth_fit(pred, pos, torch.ones(64), "drop")[0], ssi_depth_fit(pred, pos, torch.ones(64), "keep")[0])
    with pytest.raises(ValueError, match="negative_scale"):
        ssi_depth_fit(pred, pos, torch.ones(64), "clip")


def test_normal_loss_with_zero_vectors_is_finite():
    pred = torch.zeros(8, 3, requires_grad=True)
    l1, ang = normal_loss(pred, torch.zeros(8, 3), torch.ones(8))
    (l1 + ang).backward()
    assert torch.isfinite(pred.grad).all() and float(l1) == 0.0


def test_sample_pdf_with_all_zero_weights_is_uniform_and_sorted():
    bins = torch.linspace(0, 1, 9).expand(2, 9).contiguous()
    t = sample_pdf(bins, torch.zeros(2, 8), 16, None, jitter=False)
    assert torch.isfinite(t).all() and (t[:, 1:] >= t[:, :-1]).all()
    np.testing.assert_allclose(t[0].numpy(), (np.arange(16) + 0.5) / 16, atol=1e-5)


def _trainer(scene, **over):
    from methods.monosdf.trainer import MonoSDFTrainer

    cfg = typed_method_config("monosdf", "tiny", {"rays_per_batch": 64, **over})
    return MonoSDFTrainer(scene, cfg, seed=0)


def test_flush_denormals_holds_during_a_step_only_and_steps_stay_finite(tiny_scene):
    """``flush_denormals`` (config): a trainer flushes float32 denormals to 0 (FTZ / DAZ), in its OpenMP pool threads
    too, while a step runs and restores IEEE arithmetic after it (left on, a later scipy KD-tree query crashed); the
    twin ``false`` never flushes. A denormal operand (1e-39 < 1.18e-38) reads as 0 in a product and a matrix product under the flush."""
    from methods.monosdf.float_mode import flush_denormal_per_thread, pool_threads_reached

    tiny = torch.full((4, 4), 1e-39)
    seen: list[float] = []
    modes: list[list[int]] = []

    def probe(*a, **k):
        seen.append(float((tiny @ torch.eye(4))[0, 0]))
        modes.append(flush_denormal_per_thread())
        return {}

    for flush in (True, False):
        tr = _trainer(tiny_scene, flush_denormals=flush)
        tr.extra_losses.append(probe)
        assert all(np.isfinite(v) for v in tr.step().values())
        assert float((tiny * 1.0)[0, 0]) == pytest.approx(1e-39, rel=1e-3)  # IEEE again after the step
    assert seen[0] == 0.0 and seen[1] == pytest.approx(1e-39, rel=1e-3)
    if pool_threads_reached():  # every OpenMP pool thread flushes during the step, none without it
        assert set(modes[0]) == {1} and set(modes[1]) == {0}
    assert set(flush_denormal_per_thread()) <= {0, -1}


def test_camera_outside_bounding_sphere_is_a_clear_error(tiny_scene):
    with pytest.raises(BenchInputError, match="outside the bounding sphere"):
        _trainer(tiny_scene, bounding_sphere=0.1)


def test_rays_that_miss_everything_render_finite(tiny_scene):
    """Object-style field (not inside-out), every sample far from any surface: acc ~ 0, finite depth."""
    tr = _trainer(tiny_scene, inside_out=False, init_radius=0.01)
    with torch.no_grad():  # push the field far positive: nothing to hit except the sphere clamp
        tr.sdf.linears[-1].bias[0] = 50.0
    out = tr.render_pixels(0, torch.arange(32))
    for v in (out.rgb, out.depth, out.normal, out.acc):
        assert torch.isfinite(v).all()
    (out.rgb.sum() + out.depth.sum() + out.normal.sum()).backward()
    assert all(torch.isfinite(p.grad).all() for p in tr.sdf.parameters() if p.grad is not None)


def test_pruned_rendering_matches_the_full_rendering(tiny_scene):
    """``prune_weight`` (fast path) against rendering every sample with gradients (the slow twin): on a sharp
    field (small beta) most samples are pruned, and colour, depth, normals and the parameter gradients
    differ only by the weight left out (< prune_weight per sample)."""
    tr = _trainer(tiny_scene)
    with torch.no_grad():
        tr.density.beta_param.fill_(0.01)
    from methods.monosdf.render import hierarchical_samples

    pixels = torch.arange(0, 400, 5)
    r = tr.rays
    t, coarse_sdf = hierarchical_samples(tr.sdf, tr.density, r.origins[0].expand(len(pixels), 3), r.dirs[0, pixels], r.far[0, pixels],
                                         tr.cfg.near, tr.cfg.n_coarse, tr.cfg.n_fine, None, False, with_coarse_sdf=True)
    assert int(coarse_sdf.isnan().sum()) == len(pixels) * tr.cfg.n_fine
    results = []
    for prune in (0.0, 1e-4):
        for p in list(tr.sdf.parameters()) + list(tr.color.parameters()):
            p.grad = None
        out = tr.render_pixels(0, pixels, jitter=False, t=t, prune_weight=prune)
        (out.rgb.sum() + out.depth.sum() + out.normal.sum()).backward()
        results.append((out, [p.grad.clone() for p in tr.sdf.linears.parameters()]))
    (full, g_full), (pruned, g_pruned) = results
    hinted = tr.render_pixels(0, pixels, jitter=False, t=t, prune_weight=1e-4, coarse_sdf=coarse_sdf)  # coarse SDF reused
    assert hinted.kept == pruned.kept
    torch.testing.assert_close(hinted.rgb, pruned.rgb, atol=1e-6, rtol=1e-6)
    S = t.shape[1]
    assert full.kept == len(pixels) * S and pruned.kept < 0.7 * len(pixels) * S
    bound = S * 1e-4  # at most S samples, each with weight < prune_weight
    torch.testing.assert_close(pruned.rgb, full.rgb, atol=bound, rtol=0)
    torch.testing.assert_close(pruned.weights, full.weights, atol=1e-6, rtol=1e-5)  # transmittance unchanged
    torch.testing.assert_close(pruned.depth, full.depth, atol=1e-5, rtol=1e-5)
    torch.testing.assert_close(pruned.normal, full.normal, atol=bound, rtol=0)
    for a, b in zip(g_pruned, g_full):
        assert torch.isfinite(a).all()
        torch.testing.assert_close(a, b, atol=2e-2 * float(b.abs().max()) + 1e-6, rtol=0)


def test_coarse_gradient_pass_matches_the_two_pass_rendering(tiny_scene):
    """``coarse_gradient_pass`` (fast path: the coarse samples evaluated once, with gradients, then rendered from that
    pass in the sorted layout) against the two-pass sampler (slow twin: a no-gradient coarse pass, then every sample
    again with gradients): the same distances from the same random draws, and colour, depth, normals, weights, the
    per-sample and extra points' SDF gradients and every parameter gradient agree to float rounding, with a per-ray
    image slot (the colour network's per-image bias) and eikonal points riding in the pass."""
    from methods.monosdf.render import hierarchical_samples, hierarchical_samples_with_gradient, render_rays

    tr = _trainer(tiny_scene)
    tr.step(0)  # a trained, non-symmetric field (the init is a sphere)
    with torch.no_grad():
        tr.density.beta_param.fill_(0.02)
    r, cfg = tr.rays, tr.cfg
    pixels = torch.arange(0, 400, 7)
    slot = torch.tensor([0, 1])[torch.arange(len(pixels)) % 2]  # two images: per-ray slots
    origins, dirs, far = r.origins[slot], r.dirs[slot, pixels], r.far[slot, pixels]
    extra = torch.rand(40, 3, generator=torch.Generator().manual_seed(3)) * 1.6 - 0.8
    params = list(tr.sdf.parameters()) + list(tr.color.parameters()) + list(tr.density.parameters())
    results = []
    for fast in (True, False):
        gen = torch.Generator().manual_seed(11)
        for p in params:
            p.grad = None
        common = (tr.sdf, tr.color, tr.density, origins, dirs, r.z_factor[slot, pixels], far, r.world_to_cam_rot[slot], cfg.near,
                  cfg.n_coarse, cfg.n_fine)
        if fast:
            coarse = hierarchical_samples_with_gradient(tr.sdf, tr.density, origins, dirs, far, cfg.near, cfg.n_coarse, cfg.n_fine, gen, True)
            out = render_rays(*common, gen, True, extra_points=extra, image=slot, coarse=coarse)
        else:
            t = hierarchical_samples(tr.sdf, tr.density, origins, dirs, far, cfg.near, cfg.n_coarse, cfg.n_fine, gen, True)
            out = render_rays(*common, gen, True, extra_points=extra, t=t, image=slot)
        assert out.extra_grad is not None
        loss = (out.rgb.sum() + out.depth.sum() + out.normal.sum() + (out.grad[:, ::3] ** 2).sum()
                + (out.extra_grad.norm(dim=-1) - 1).square().sum())
        loss.backward()
        results.append((out, [p.grad.clone() for p in params]))
    (fast, g_fast), (slow, g_slow) = results
    assert fast.kept == slow.kept == len(pixels) * cfg.samples_per_ray() and fast.kept_index is None
    torch.testing.assert_close(fast.t, slow.t, atol=1e-6, rtol=0)
    for name in ("rgb", "depth", "normal", "weights", "grad", "sdf", "extra_grad"):
        torch.testing.assert_close(getattr(fast, name), getattr(slow, name), atol=1e-5, rtol=1e-4, msg=name)
    for a, b in zip(g_fast, g_slow):
        assert torch.isfinite(a).all()
        torch.testing.assert_close(a, b, atol=1e-5 * float(b.abs().max()) + 1e-7, rtol=1e-3)
    with pytest.raises(ValueError, match="coarse="):
        gen = torch.Generator().manual_seed(11)
        coarse = hierarchical_samples_with_gradient(tr.sdf, tr.density, origins, dirs, far, cfg.near, cfg.n_coarse, cfg.n_fine, gen, True)
        render_rays(*common, gen, True, image=slot, coarse=coarse, prune_weight=1e-4)


def test_coarse_gradient_pass_trains_like_the_two_pass_sampler(tiny_scene):
    """Whole steps: ``coarse_gradient_pass: true`` and ``false`` from the same seed give the same losses and parameters
    over a few steps (float rounding apart; the random draws are the same), with and without the smoothness term's
    jittered points and in a pruning step (which keeps the two-pass sampler). Adam moves a grid entry whose gradient is
    ~0 by up to its learning rate either way on a rounding difference: a few such entries may differ, no more."""
    for over in ({}, {"smooth_weight": 0.0}, {"prune_weight": 1e-4}):
        trainers = [_trainer(tiny_scene, coarse_gradient_pass=fast, **over) for fast in (True, False)]
        if "prune_weight" in over:
            for tr in trainers:
                tr._prunable_frac = 0.5  # this step prunes
        logs = [[tr.step(v) for v in (0, 1, 2)] for tr in trainers]
        for a, b in zip(*logs):
            for k in b:
                assert a[k] == pytest.approx(b[k], rel=1e-3, abs=1e-6), (over, k)
        for (name, pa), pb in zip(trainers[0].sdf.named_parameters(), trainers[1].sdf.parameters()):
            if name.startswith("grid."):
                assert float(((pa - pb).abs() > 1e-5).float().mean()) < 1e-4, (over, name)
                assert float((pa - pb).abs().max()) <= 3 * trainers[0].optim.param_groups[0]["lr"], (over, name)
            else:
                torch.testing.assert_close(pa, pb, atol=1e-4, rtol=1e-3, msg=f"{over} {name}")


def test_pruned_training_steps_are_finite(tiny_scene):
    for mode in ("random", "max_weight"):
        tr = _trainer(tiny_scene, prune_weight=1e-4, eikonal_ray_sample=mode)
        with torch.no_grad():
            tr.density.beta_param.fill_(0.005)
        for view in (0, 1):
            logs = tr.step(view)
            assert all(np.isfinite(v) for v in logs.values()), (mode, logs)
        assert all(torch.isfinite(p).all() for p in tr.sdf.parameters())


def test_training_steps_are_finite_with_all_zero_and_constant_priors(tiny_scene):
    tr = _trainer(tiny_scene)
    tr.prior_depth[0] = 0.0  # all-zero prior in view 0
    tr.prior_depth[1] = 1.5  # constant prior in view 1
    for view in (0, 1, 2):
        logs = tr.step(view)
        assert all(np.isfinite(v) for v in logs.values()), (view, logs)
        assert all(torch.isfinite(p).all() for p in tr.sdf.parameters())
    assert tr.step(0)["depth"] == 0.0


def test_checkpoint_resume_continues_exactly(tiny_scene, tmp_path):
    a = _trainer(tiny_scene)
    for _ in range(6):
        a.step()
    b = _trainer(tiny_scene)
    for _ in range(3):
        b.step()
    b.save(tmp_path / "ckpt.pt")
    c = _trainer(tiny_scene)
    c.load(tmp_path / "ckpt.pt")
    for _ in range(3):
        c.step()
    for pa, pc in zip(a.sdf.parameters(), c.sdf.parameters()):
        torch.testing.assert_close(pa, pc, atol=1e-6, rtol=1e-5)


def test_fit_produces_world_mesh_snapshots(tiny_scene):
    from methods.monosdf.method import MonoSDF

    cfg = method_config("monosdf", "tiny", {"iterations": 20, "rays_per_batch": 64, "mesh_resolution": 32})
    art = MonoSDF().fit(tiny_scene, cfg, seed=0)
    assert [s.fraction for s in art.snapshots] == [0.25, 0.5, 1.0]
    assert art.iterations == 20 and set(art.timings) >= {"train", "mesh"}
    mesh = art.final.mesh
    assert len(mesh.faces) > 0
    gt = tiny_scene.load_gt_mesh()
    lo, hi = gt.bounds
    centre = (lo + hi) / 2
    # world metres: the mesh lies within the bounding sphere of the scene (a few metres), not the unit cube
    assert np.linalg.norm(mesh.vertices - centre, axis=1).max() < 1.2 * np.linalg.norm(hi - lo)
    assert np.ptp(mesh.vertices, axis=0).max() > 1.5


def test_smoothness_loss_zero_for_parallel_normals_and_finite_for_zero_gradients():
    g = torch.randn(40, 3)
    assert float(smoothness_loss(g, 3.0 * g)) < 1e-4  # same directions, any length
    z = torch.zeros(10, 3, requires_grad=True)
    loss = smoothness_loss(z, torch.randn(10, 3))
    loss.backward()
    assert torch.isfinite(loss) and torch.isfinite(z.grad).all()
    assert abs(float(smoothness_loss(g, -g)) - 2.0) < 1e-3  # opposite normals: |n1 - n2| = 2


def test_appearance_codes_are_per_image_and_trained(tiny_scene):
    """appearance_dim > 0: one code per training image, the colour depends on it, and a step moves only
    the code of the image it rendered (MonoSDF's per_image_code)."""
    tr = _trainer(tiny_scene, appearance_dim=8, pe_frequencies=6, smooth_weight=0.005, eikonal_ray_sample="random")
    assert tuple(tr.color.codes.shape) == (len(tr.views), 8)
    before = tr.color.codes.detach().clone()
    logs = tr.step(view=2)
    assert all(np.isfinite(v) for v in logs.values()) and "smooth" in logs
    moved = (tr.color.codes.detach() - before).abs().sum(-1) > 0
    assert moved[2] and int(moved.sum()) == 1
    with torch.no_grad():
        tr.color.codes[0] = 1.0
        tr.color.codes[1] = -1.0
        px = torch.arange(16)
        a, b = tr.render_pixels(0, px, jitter=False).rgb, tr.render_pixels(1, px, jitter=False).rgb
    assert torch.isfinite(a).all() and not torch.allclose(a, b)


def test_diagnostics_report_depth_error_and_mesh_agreement(tiny_scene):
    tr = _trainer(tiny_scene, diag_views=2, diag_stride=4)
    for _ in range(3):
        tr.step()
    d = tr.diagnostics(tr.extract_mesh(32))
    assert {"beta", "loss_color", "loss_eikonal", "depth_err_median", "mesh_ahead_frac", "sampler_gap_median",
            "samples_weighted", "edge_px_frac", "depth_err_interior_median", "depth_fit_scale_iqr"} <= set(d)
    assert 0 < d["samples_weighted"] <= tr.cfg.n_coarse + tr.cfg.n_fine
    assert all(np.isfinite(v) for v in d.values())
    assert 0.0 <= d["mesh_ahead_frac"] <= 1.0 and d["depth_err_median"] >= 0.0
    assert "loss_color" not in tr.diagnostics()  # averages reset at each call


def test_multi_image_batches_fit_depth_per_image(tiny_scene):
    """images_per_batch = 3: the rays come from 3 images (their 3 codes move), the step is finite, and
    the depth term is the mean of three per-image scale-and-shift fits: a prior that is a different
    affine map of the rendered depth in each image costs ~0, which one joint fit could not do."""
    tr = _trainer(tiny_scene, appearance_dim=4, images_per_batch=3, rays_per_batch=96)
    before = tr.color.codes.detach().clone()
    logs = tr.step()
    assert all(np.isfinite(v) for v in logs.values())
    assert int(((tr.color.codes.detach() - before).abs().sum(-1) > 0).sum()) == 3
    with torch.no_grad():
        depth = torch.stack([tr.render_pixels(v, torch.arange(32), jitter=False).depth for v in range(len(tr.views))])
    tr.prior_depth = torch.zeros_like(tr.prior_depth)
    for v in range(len(tr.views)):
        tr.prior_depth[v, :32] = depth[v] * (1.0 + v) + 0.1 * v
    tr.pixel_sampler = lambda v, n, g: torch.arange(n)
    logs = tr.step()
    assert logs["depth"] < 1e-3


def test_coarse_to_fine_levels_switch_on_along_the_schedule(tiny_scene):
    """grid_levels_initial = 2, one more level every 25 % of the schedule; the inactive levels' table
    entries receive no gradient."""
    tr = _trainer(tiny_scene, grid_levels_initial=2, grid_level_every=0.25, iterations=8)
    spec = tr.sdf.grid.spec
    tr.step()
    assert tr.sdf.active_levels == 2
    g = tr.sdf.grid.table.grad
    assert g is None or float(g[spec.offsets[2]:].abs().sum()) == 0.0
    for _ in range(5):
        tr.step()
    assert tr.sdf.active_levels == 2 + 2  # step 5 of 8 = 62.5 %: two more levels


def test_depth_warmup_ramps_the_depth_weight_only(tiny_scene):
    """depth_warmup = 0.5 of 8 steps: the depth term contributes nothing at step 0 (its value is still
    logged), half its weight at step 2 and all of it from step 4; warm-up 0 is MonoSDF (full weight)."""
    tr = _trainer(tiny_scene, depth_warmup=0.5, iterations=8)
    ramp = []
    for _ in range(6):
        ramp.append(tr._warmup("depth_warmup"))
        logs = tr.step()
        assert np.isfinite(logs["depth"])
    assert ramp == [0.0, 0.25, 0.5, 0.75, 1.0, 1.0]
    assert _trainer(tiny_scene)._warmup("depth_warmup") == 1.0
    # at step 0 the total loss has no depth part
    tr0 = _trainer(tiny_scene, depth_warmup=0.5, iterations=8)
    logs = tr0.step(0)
    rest = sum(getattr(tr0.cfg, f"{k}_weight") * logs[k] for k in ("color", "eikonal", "smooth"))
    rest += tr0.cfg.normal_weight * (logs["normal_l1"] + logs["normal_cos"])
    assert logs["depth"] > 0 and abs(logs["loss"] - rest) < 1e-5 * max(1.0, abs(rest))


def test_lr_warmup_ramps_every_group_from_one_percent(tiny_scene):
    tr = _trainer(tiny_scene, lr_warmup=0.5, iterations=8, lr_decay=1.0)
    seen = []
    for _ in range(5):
        tr.step()
        seen.append([g["lr"] / b for g, b in zip(tr.optim.param_groups, tr.base_lrs)])
    np.testing.assert_allclose(np.array(seen), np.array([[r] * len(tr.base_lrs) for r in (0.01, 0.25, 0.5, 0.75, 1.0)]))


@pytest.mark.slow
@pytest.mark.skipif(not fast_available(), reason="no C++ compiler")
def test_stale_torch_build_lock_does_not_hang_the_next_run():
    """A build killed mid-way leaves torch's ``lock`` file; the next process must load the kernel, not
    wait forever. A stale lock is planted in the built kernel's folder (no other process builds there:
    the test session holds no ``bench-build.lock``)."""
    import subprocess
    import sys
    from pathlib import Path

    from methods.monosdf.grid import _KERNEL

    built = _KERNEL.build_dir()
    (built / "lock").write_text("")
    code = "from methods.monosdf.grid import _load_extension; import sys; sys.exit(0 if _load_extension() is not None else 3)"
    res = subprocess.run([sys.executable, "-c", code], cwd=Path(__file__).resolve().parents[2], timeout=240,
                         capture_output=True, text=True)
    assert res.returncode == 0, res.stderr[-2000:]
    assert not (built / "lock").exists() and "compiling" not in res.stderr


def test_build_lock_times_out_with_the_lock_file_named(tmp_path):
    import fcntl

    from methods.monosdf.grid import build_lock

    with open(tmp_path / "bench-build.lock", "a+") as held:  # another live builder holds it
        fcntl.flock(held, fcntl.LOCK_EX)
        with pytest.raises(TimeoutError, match="bench-build.lock"):
            with build_lock(tmp_path, timeout_s=0.6):
                pass


def test_depth_edges_mark_both_sides_of_a_jump_only():
    from methods.monosdf.trainer import depth_edges

    d = np.full((6, 8), 2.0)
    d[:, 4:] = 3.0  # a 1 m jump between columns 3 and 4
    e = depth_edges(d)
    assert e[:, 2:6].all() and not e[:, :2].any() and not e[:, 6:].any()
    assert not depth_edges(np.full((5, 5), 2.0) + np.arange(5) * 0.05).any()  # a slanted plane: no edge
    z = np.full((5, 5), 2.0)
    z[2, 2] = 0.0  # an invalid pixel: its neighbours are a border
    assert depth_edges(z)[1:4, 1:4].all() and not depth_edges(z)[0, 0]


def test_beta_floor_decays_linearly_to_beta_min(tiny_scene):
    tr = _trainer(tiny_scene, beta_floor=0.08, beta_floor_until=0.5, iterations=8)
    mins = []
    for _ in range(6):
        tr.step()
        mins.append(tr.density.beta_min)
        assert float(tr.density.beta()) >= tr.density.beta_min
    np.testing.assert_allclose(mins, [1e-4 + 0.08 * max(0.0, 1 - k / 4) for k in range(6)], atol=1e-9)
    assert _trainer(tiny_scene).density.beta_min == pytest.approx(1e-4)


def test_metric_depth_fit_diagnostic_pins_the_scale():
    """``depth_fit: metric`` (diagnostic): no fit, scale fixed, shift 0: an affine copy of the prior that the
    scale-and-shift-invariant loss accepts is penalised; the exact match is not; gradients are finite."""
    from methods.monosdf.losses import ssi_depth_fit

    prior = torch.linspace(1.0, 4.0, 64)
    w = torch.ones(64)
    exact = (prior / 3.15).requires_grad_(True)
    shrunk = (0.9 * prior / 3.15 + 0.05).requires_grad_(True)
    assert float(ssi_depth_fit(shrunk, prior, w)[0]) < 1e-8  # SSI: the shrunk copy is as good as the truth
    loss_exact, s = ssi_depth_fit(exact, prior, w, fixed_scale=3.15)
    loss_shrunk, _ = ssi_depth_fit(shrunk, prior, w, fixed_scale=3.15)
    assert float(loss_exact) < 1e-10 and float(s) == pytest.approx(3.15) and float(loss_shrunk) > 1e-3
    loss_shrunk.backward()
    assert torch.isfinite(shrunk.grad).all() and float(shrunk.grad.abs().sum()) > 0


def test_code_form_of_the_prior_losses():
    """The MonoInstance release's depth loss: binary-mask fit over rays whose SDF changes sign, c-weighted
    residual / (2 x masked rays); 0 (finite, zero gradient) without masked rays or with all weights 0. Its
    normal terms are means over all rays of c x term."""
    from methods.monosdf.losses import ssi_depth_fit_code

    torch.manual_seed(0)
    pred = (torch.rand(64) + 0.5).requires_grad_(True)
    target = 2.0 * pred.detach() + 0.3 + 0.05 * torch.randn(64)
    w = torch.rand(64)
    crosses = torch.rand(64) > 0.3
    loss, scale = ssi_depth_fit_code(pred, target, w, crosses)
    m = crosses.float()
    s, t = solve_scale_shift(pred.detach(), target, m)
    want = (m * w * (s * pred.detach() + t - target) ** 2).sum() / (2 * m.sum())
    assert float(loss) == pytest.approx(float(want), rel=1e-4) and float(scale) == pytest.approx(float(s), rel=1e-4)
    loss.backward()
    assert torch.isfinite(pred.grad).all() and float(pred.grad[~crosses].abs().max()) == 0.0
    for crossing, weight in ((torch.zeros(64, dtype=torch.bool), w), (crosses, torch.zeros(64))):
        p = pred.detach().clone().requires_grad_(True)
        zero, _ = ssi_depth_fit_code(p, target, weight, crossing)
        zero.backward()
        assert float(zero) == 0.0 and torch.isfinite(p.grad).all()
    n = torch.nn.functional.normalize(torch.randn(64, 3), dim=-1)
    l1, ang = normal_loss(n, n, w, reduce="rays")
    assert float(l1) == pytest.approx(0.0, abs=1e-6) and float(ang) == pytest.approx(0.0, abs=1e-6)
    l1, ang = normal_loss(n, -n, torch.ones(64), reduce="rays")
    assert float(ang) == pytest.approx(2.0, abs=1e-5)


def test_trainer_with_the_code_form_of_the_prior_losses_steps_finitely(tiny_scene):
    tr = _trainer(tiny_scene, prior_loss_form="code")
    for _ in range(3):
        logs = tr.step()
    assert all(np.isfinite(v) for v in logs.values()) and {"depth", "normal_l1"} <= set(logs)
    with pytest.raises(ValueError, match="prior_loss_form"):
        _trainer(tiny_scene, prior_loss_form="paper")


@pytest.mark.parametrize("prune", [0.0, 1e-4])
def test_eikonal_on_every_ray_sample_like_the_release(tiny_scene, prune):
    """``eikonal_ray_sample: all`` (MonoInstance release): eikonal on every rendered ray sample, smoothness
    against a jittered neighbour of each, no uniform points; finite losses and gradients, also pruned."""
    tr = _trainer(tiny_scene, eikonal_ray_sample="all", prune_weight=prune)
    for _ in range(3):
        logs = tr.step()
    assert np.isfinite(logs["eikonal"]) and np.isfinite(logs["smooth"]) and logs["smooth"] > 0
    assert all(torch.isfinite(p.grad).all() for p in tr.sdf.parameters() if p.grad is not None)
    with pytest.raises(ValueError, match="eikonal_ray_sample"):
        _trainer(tiny_scene, eikonal_ray_sample="every").step()


def test_step_labels_every_phase_the_step_benchmark_times(tiny_scene):
    """benchmarks/bench_monosdf_step.py --phases reads these record_function labels: a renamed or dropped
    label would silently vanish from its table, so a pruned step and an unpruned one (``coarse_gradient_pass``: the
    coarse pass with gradients) must show every one of them between them."""
    import importlib.util
    from pathlib import Path

    from torch.profiler import ProfilerActivity, profile

    path = Path(__file__).resolve().parents[2] / "benchmarks" / "bench_monosdf_step.py"
    spec = importlib.util.spec_from_file_location("bench_monosdf_step", path)
    assert spec is not None and spec.loader is not None
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    tr = _trainer(tiny_scene, prune_weight=1e-4)
    seen: set[str] = set()
    for frac in (0.0, 1.0):  # 0: the pruned path (its extra no-gradient pass) from the first step; 1: no pruning
        tr._prunable_frac = frac
        with profile(activities=[ProfilerActivity.CPU]) as prof:
            tr.step(0)
        seen |= {e.key for e in prof.key_averages()}
    assert set(bench.PHASES) <= seen, set(bench.PHASES) - seen


@pytest.mark.parametrize("source_format,bias", [("scannet", 0.9), ("replica", 0.6), ("dtu", 0.6), ("llff", 0.9)])
def test_init_radius_auto_is_monosdfs_bias_in_monosdfs_normalisation(tiny_scene, monkeypatch, source_format, bias):
    """``init_radius: auto`` (the default): MonoSDF's bias for the scene's dataset format (ScanNet 0.9, Replica /
    DTU 0.6; another format ScanNet's), for a room converted from MonoSDF's normalisation (one unit = (largest
    camera-position extent + 3 m) / 2) into the scene's. Hand case: cameras spanning 2 m along x -> MonoSDF's unit
    2.5 m; a scene unit of 5 m -> half the bias. An object keeps the bias. The trainer builds its init sphere with
    the resolved radius; a number overrides it; anything else is an error."""
    import methods.monosdf.trainer as trainer_module
    from methods.monosdf.trainer import resolve_init_radius

    poses = np.repeat(np.eye(4)[None], 3, axis=0)
    poses[:, :3, 3] = [[0.0, 0.0, 1.5], [1.0, 0.5, 1.4], [2.0, 0.2, 1.6]]
    room = dataclasses.replace(tiny_scene, source_format=source_format, cam_to_world=poses, scale_mat=np.diag([5.0, 5.0, 5.0, 1.0]))
    assert resolve_init_radius("auto", room) == pytest.approx(bias * 2.5 / 5.0)
    assert resolve_init_radius("auto", dataclasses.replace(room, kind="object")) == bias
    assert resolve_init_radius(0.75, room) == 0.75
    for bad in ("big", -0.5, True):
        with pytest.raises(ValueError, match="init_radius"):
            resolve_init_radius(bad, room)
    scene = dataclasses.replace(tiny_scene, source_format=source_format)
    built: list[float] = []
    real = trainer_module.SDFNetwork
    monkeypatch.setattr(trainer_module, "SDFNetwork", lambda *a, **kw: built.append(kw["init_radius"]) or real(*a, **kw))
    _trainer(scene)
    _trainer(scene, init_radius=0.75)
    assert built == [resolve_init_radius("auto", scene), 0.75]
    assert 0.3 < built[0] < 1.0
