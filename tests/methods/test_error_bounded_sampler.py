"""VolSDF's error-bounded sampler (``sampler: error_bounded``): its bounds against brute force, its samples on
a known surface, hard cases finite, and the trainer with it."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from methods.monosdf.error_bounded import error_bounded_samples, interval_distance_bound, opacity_error_bound
from methods.monosdf.field import LaplaceDensity
from methods.monosdf.render import composite_weights, hierarchical_samples
from methods.registry import typed_method_config


class PlaneSDF:
    """SDF of the plane z = ``depth`` seen from the origin, positive on the camera's side (a room wall), scaled
    by ``scale`` (1 = a distance function; 1e30 = an extreme field)."""

    def __init__(self, depth: float, scale: float = 1.0) -> None:
        self.depth, self.scale = depth, scale

    def __call__(self, x: torch.Tensor, with_gradient: bool = False) -> tuple[torch.Tensor, None, None]:
        return self.scale * (self.depth - x[:, 2]), None, None


def _rays(n: int, seed: int = 0) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    g = torch.Generator().manual_seed(seed)
    dirs = torch.nn.functional.normalize(torch.randn(n, 3, generator=g) * torch.tensor([0.3, 0.3, 0.0]) + torch.tensor([0.0, 0.0, 1.0]), dim=-1)
    return torch.zeros(n, 3), dirs, torch.full((n,), 3.0)


def _true_distance_bound(a: float, b: float, c: float, n: int = 200001) -> float:
    """Brute force of what ``d*`` bounds: the distance from the segment [0, a] (on the x axis) to the nearest
    point outside both balls |y| < b and |y - (a, 0)| < c. That point lies on the boundary of the balls'
    union, so both circles are walked densely (the problem is symmetric about the axis) and the points
    inside the other ball dropped."""
    theta = np.linspace(0.0, np.pi, n)
    on_b = np.stack([b * np.cos(theta), b * np.sin(theta)], -1)
    on_c = np.stack([a + c * np.cos(theta), c * np.sin(theta)], -1)
    boundary = np.concatenate([on_b[np.hypot(on_b[:, 0] - a, on_b[:, 1]) >= c], on_c[np.hypot(on_c[:, 0], on_c[:, 1]) >= b]])
    if b + c <= a:  # the balls leave a gap on the segment itself
        return 0.0
    return float(np.hypot(boundary[:, 0] - np.clip(boundary[:, 0], 0.0, a), boundary[:, 1]).min())


def test_distance_bound_never_exceeds_the_brute_force_and_is_tight_when_the_spheres_meet_above_the_segment():
    rng = np.random.default_rng(0)
    tight = 0
    for _ in range(60):
        a, b, c = rng.uniform(0.05, 1.0, 3)
        got = float(interval_distance_bound(torch.tensor([[0.0, a]]), torch.tensor([[b, c]], dtype=torch.float32))[0, 0])
        true = _true_distance_bound(a, b, c)
        cell = 1e-4 * (a + b + c)
        assert got <= true + 2 * cell, (a, b, c, got, true)
        if a * a + b * b > c * c and a * a + c * c > b * b and b + c > a:  # acute: the height case, exact
            assert got == pytest.approx(true, abs=2 * cell)
            tight += 1
        if b + c <= a:  # a gap between the balls on the segment
            assert got == 0.0
    assert tight > 5
    # the SDF changes sign across the interval: the surface is in it
    assert float(interval_distance_bound(torch.tensor([[0.0, 0.1]]), torch.tensor([[0.05, -0.05]]))[0, 0]) == 0.0


def test_opacity_error_bound_holds_against_the_exact_opacity_of_a_plane():
    """VolSDF Theorem 1, checked: the quadrature's opacity (left Riemann sum of sigma over the samples) differs
    from the exact one (dense integral) by at most the bound, on every ray and at every sample."""
    origins, dirs, _ = _rays(16)
    plane = PlaneSDF(1.0)
    for beta_value in (0.2, 0.05):
        density = LaplaceDensity(beta_value, 0.0)
        beta = density.beta().detach()
        t = torch.linspace(0.02, 3.0, 64).expand(16, 64).contiguous()
        sdf = plane((origins[:, None] + dirs[:, None] * t[..., None]).reshape(-1, 3))[0].reshape(16, 64)
        bound = opacity_error_bound(beta, sdf, t, interval_distance_bound(t, sdf), density)
        dense_t = torch.linspace(0.02, 3.0, 200001, dtype=torch.float64)
        for r in range(16):
            sigma = density(1.0 - dense_t * dirs[r, 2].double(), beta.double())
            exact = torch.cat([torch.zeros(1, dtype=torch.float64), torch.cumsum(0.5 * (sigma[1:] + sigma[:-1]) * dense_t.diff(), 0)])
            exact_at = np.interp(t[r].numpy(), dense_t.numpy(), exact.numpy())
            est = np.concatenate([[0.0], np.cumsum((t[r].diff() * density(sdf[r], beta)[:-1]).numpy())])
            err = np.abs(np.exp(-exact_at) - np.exp(-est)).max()
            assert err <= float(bound[r]) + 1e-4, (beta_value, r, err, float(bound[r]))


def test_samples_crowd_a_sharp_surface_and_render_its_depth_better_than_the_hierarchical_sampler():
    origins, dirs, far = _rays(128)
    true = 1.0 / dirs[:, 2]
    plane = PlaneSDF(1.0)
    for beta_value in (0.01, 1e-3):
        density = LaplaceDensity(beta_value, 1e-4)
        t, known = error_bounded_samples(plane, density, origins, dirs, far, 0.02, 128, 64, 32, 0.1, 10, 5,
                                         torch.Generator().manual_seed(0), True, with_coarse_sdf=True)
        assert t.shape == (128, 64 + 32 + 2) and torch.isfinite(t).all() and (t.diff(dim=-1) >= 0).all()
        assert (t >= 0.02 - 1e-6).all() and (t <= 3.0 + 1e-6).all()
        assert (known.isnan().sum(-1) == 64 + 2).all()  # the final draw, near and far are new; the 32 extra are known
        pts = (dirs[:, None] * t[..., None]).reshape(-1, 3)
        true_sdf = plane(pts)[0].reshape(t.shape)
        torch.testing.assert_close(known[~known.isnan()], true_sdf[~known.isnan()])
        assert float(((t - true[:, None]).abs() < 10 * beta_value).sum(-1).float().mean()) >= 60  # the final draw sits on it
        depth = lambda tt: (composite_weights(1.0 - tt * dirs[:, 2:3], tt, density) * tt).sum(-1)  # noqa: E731
        err_eb = float((depth(t) - true).abs().max().detach())
        th = hierarchical_samples(plane, density, origins, dirs, far, 0.02, 32, 32, None, False)
        err_h = float((depth(th) - true).abs().max().detach())
        assert err_eb < 3 * beta_value and err_eb < err_h, (beta_value, err_eb, err_h)


@pytest.mark.parametrize("case", ["beta_min", "miss", "huge"])
def test_hard_cases_give_finite_sorted_samples_inside_the_ray(case):
    origins, dirs, far = _rays(64)
    beta = {"beta_min": 0.0, "miss": 0.1, "huge": 1e-3}[case]
    density = LaplaceDensity(beta, 1e-4)
    plane = {"beta_min": PlaneSDF(1.0), "miss": PlaneSDF(50.0), "huge": PlaneSDF(1.0, scale=1e30)}[case]
    for jitter in (True, False):
        t = error_bounded_samples(plane, density, origins, dirs, far, 0.02, 32, 16, 8, 0.1, 10, 5,
                                  torch.Generator().manual_seed(1), jitter)
        assert torch.isfinite(t).all() and (t.diff(dim=-1) >= 0).all()
        assert (t >= 0.02 - 1e-6).all() and (t <= 3.0 + 1e-6).all()
        assert t.shape == (64, 16 + 8 + 2)


def test_deterministic_without_jitter_and_per_generator_with_it():
    origins, dirs, far = _rays(32)
    density = LaplaceDensity(0.02, 1e-4)
    args = (PlaneSDF(1.0), density, origins, dirs, far, 0.02, 64, 32, 16, 0.1, 10, 5)
    a = error_bounded_samples(*args, None, False)
    b = error_bounded_samples(*args, None, False)
    assert torch.equal(a, b)
    c = error_bounded_samples(*args, torch.Generator().manual_seed(3), True)
    d = error_bounded_samples(*args, torch.Generator().manual_seed(3), True)
    assert torch.equal(c, d) and not torch.equal(a, c)


def test_lemma_2_initial_beta_meets_eps_on_any_sdf():
    """The starting beta+ (VolSDF Lemma 2: sqrt(sum delta^2 / (4 log(1 + eps)))) bounds the error by eps whatever
    the SDF: d* >= 0 makes exp(-d*/beta) <= 1 and the transmittance <= 1."""
    t = torch.sort(torch.rand(8, 40, generator=torch.Generator().manual_seed(0)) * 2, -1).values
    sdf = torch.randn(8, 40, generator=torch.Generator().manual_seed(1)) * 0.3
    eps = 0.1
    beta = torch.sqrt((t.diff(dim=-1) ** 2).sum(-1) / (4 * math.log(1 + eps)))
    bound = opacity_error_bound(beta[:, None], sdf, t, interval_distance_bound(t, sdf), LaplaceDensity(0.1, 0.0))
    assert (bound <= eps + 1e-6).all()


def test_config_counts_its_samples_and_the_trainer_steps_with_it(tiny_scene):
    from methods.monosdf.trainer import MonoSDFTrainer

    over = {"rays_per_batch": 32, "sampler": "error_bounded", "eb_n_eval": 32, "eb_n_final": 16, "eb_n_extra": 8}
    cfg = typed_method_config("monosdf", "tiny", over)
    assert cfg.samples_per_ray() == 16 + 8 + 2
    assert typed_method_config("monosdf", "tiny", {}).samples_per_ray() == 64
    for prune in (0.0, 1e-4):
        tr = MonoSDFTrainer(tiny_scene, typed_method_config("monosdf", "tiny", {**over, "prune_weight": prune}), seed=0)
        with torch.no_grad():
            tr.density.beta_param.fill_(0.01)
        for _ in range(3):
            logs = tr.step()
            assert all(np.isfinite(v) for v in logs.values())
        for p in tr.sdf.parameters():
            assert p.grad is None or torch.isfinite(p.grad).all()
        depth = tr.render_view_depth(0, stride=8)
        assert np.isfinite(depth).all() and (depth > 0).all()
