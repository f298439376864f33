"""MonoSDF training on a Scene: one image x ``rays_per_batch`` rays per step (MonoSDF's batching),
colour L1 + eikonal + scale-and-shift-invariant depth + normal (L1 + angular) losses, Adam with the
grid at ``grid_lr_factor`` x the MLP learning rate and exponential decay to ``lr_decay`` x.

Hooks used by MonoInstance (``methods/monoinstance``) without copying this loop:

* ``prior_weight``: (V, H*W) per-pixel weights of the depth/normal losses (all 1 for MonoSDF);
* ``pixel_sampler``: ``(view, n, generator) -> (n,) pixel indices`` (uniform for MonoSDF);
* ``extra_losses``: callables ``(trainer, view, pixels, render_output) -> {name: (weight, loss)}``.

Checkpoints hold the networks, the optimiser, the step and the random-generator state, so a resumed
run continues exactly where it stopped.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable, cast

import numpy as np
import torch
import trimesh
from torch.profiler import record_function

from bench.data.config import config_record
from bench.data.normalisation import monosdf_indoor_unit_m
from bench.data.scene import Scene
from methods.base import Snapshot
from methods.cpp_build import OwnClock
from methods.monosdf.config import MonoSDFConfig
from methods.monosdf.error_bounded import error_bounded_samples
from methods.monosdf.field import ColorNetwork, LaplaceDensity, SDFNetwork
from methods.monosdf.float_mode import denormals_flushed
from methods.monosdf.grid import make_grid_spec
from methods.monosdf.losses import color_loss, eikonal_loss, normal_loss, smoothness_loss, ssi_depth_fit, ssi_depth_fit_code
from methods.monosdf.rays import build_rays, normalisation
from methods.monosdf.render import CoarseGradientPass, RenderOutput, hierarchical_samples, hierarchical_samples_with_gradient, render_depth, render_rays

PixelSampler = Callable[[int, int, torch.Generator], torch.Tensor]


def resolve_inside_out(value: Any, scene: Scene) -> bool:
    """The geometric-init orientation: ``true`` for rooms (cameras inside the surface), ``false`` for
    objects (an outward sphere, MonoSDF/VolSDF DTU), ``"auto"`` from ``scene.kind`` (room -> true)."""
    if value == "auto":
        return scene.kind == "room"
    if isinstance(value, bool):
        return value
    raise ValueError(f"inside_out must be true, false or 'auto', got {value!r}")


# Geometric-init sphere radius (``init_radius: auto``). MonoSDF's configs set it per dataset (the IDR bias: 0.9 for
# ScanNet, 0.6 for Replica and DTU) in MonoSDF's own normalisation of an indoor scene, where one unit is
# (largest extent of the camera positions + 3 m) / 2 (preprocess/scannet_to_monosdf.py: "+3 because we assume each
# camera sees 1.5 meters forward"). A room normalised otherwise (the shipped rooms: the unit sphere holds the room,
# ``room.normalise: room``) gets the same bias converted into its units (a factor 1 under ``room.normalise:
# cameras``): the sphere then lies where MonoSDF's would, relative to the cameras (docs/studies/no-prior-fog-mode.md: at 0.9 of the room's own sphere it lies 0.7-1.6 m behind the
# walls, and a no-prior run fogs). Objects and other kinds keep the bias as it is (their normalisation is MonoSDF's).
# MonoSDF's Replica data was normalised from the GT mesh's bounding box instead (its script: github.com/autonomousvision/monosdf/issues/69,
# scale line not seen); the camera rule stands in for it on Replica-format rooms (docs/studies/no-prior-fog-mode.md).
INIT_RADIUS_OF_FORMAT = {"scannet": 0.9, "replica": 0.6, "dtu": 0.6}
DEFAULT_INIT_RADIUS = 0.9


def resolve_init_radius(value: Any, scene: Scene) -> float:
    """The geometric-init sphere radius in the scene's normalised units: ``value`` itself, or for ``"auto"``
    MonoSDF's bias for ``scene.source_format`` (:data:`INIT_RADIUS_OF_FORMAT`, else :data:`DEFAULT_INIT_RADIUS`),
    for a room converted from MonoSDF's normalisation (:func:`bench.data.normalisation.monosdf_indoor_unit_m`) into the scene's
    (``scale_mat``: metres per unit)."""
    if value == "auto":
        bias = INIT_RADIUS_OF_FORMAT.get(scene.source_format, DEFAULT_INIT_RADIUS)
        if scene.kind != "room":
            return bias
        return bias * monosdf_indoor_unit_m(scene.cam_to_world) / scene.metres_per_unit
    if isinstance(value, (int, float)) and not isinstance(value, bool) and value > 0:
        return float(value)
    raise ValueError(f"init_radius must be a positive number or 'auto', got {value!r}")


PRUNE_WORTH = 0.75  # prune_weight: prune only while the last step had at most this fraction of samples above it
                   # (the no-gradient pass over all samples costs ~15 % of a step: measured, docs/studies/monosdf-speed.md)
WEIGHTED_SAMPLE = 1e-4  # a sample with a smaller rendering weight counts as empty space in ``samples_weighted``


def depth_edges(depth: np.ndarray, jump_m: float = 0.10) -> np.ndarray:
    """(H, W) bool: pixels within 1 px (8-neighbourhood) of a depth discontinuity, i.e. a 4-neighbour
    pair of valid depths (> 0, metres) differing by more than ``jump_m``, or a valid / invalid border."""
    d = np.asarray(depth, dtype=np.float64)
    valid = d > 0
    jump = np.zeros(d.shape, dtype=bool)
    for axis in (0, 1):
        a = np.swapaxes(d, 0, axis)
        v = np.swapaxes(valid, 0, axis)
        pair = ((np.abs(a[1:] - a[:-1]) > jump_m) & v[1:] & v[:-1]) | (v[1:] != v[:-1])
        j = np.swapaxes(jump, 0, axis)
        j[1:] |= pair
        j[:-1] |= pair
    grown = jump.copy()
    grown[1:] |= jump[:-1]
    grown[:-1] |= jump[1:]
    out = grown.copy()
    out[:, 1:] |= grown[:, :-1]
    out[:, :-1] |= grown[:, 1:]
    return out


class MonoSDFTrainer:
    """Holds the scene's training data, the networks and the optimiser."""

    def __init__(self, scene: Scene, cfg: MonoSDFConfig, seed: int) -> None:
        self.scene, self.cfg, self.seed = scene, cfg, seed
        torch.manual_seed(seed)
        self.gen = torch.Generator().manual_seed(seed)
        self.views = scene.view_indices("train")
        self.radius = float(cfg.bounding_sphere)
        self.rays = build_rays(scene, self.views, self.radius)
        V, HW = len(self.views), scene.height * scene.width
        self.rgb = torch.from_numpy(scene.images[self.views].reshape(V, HW, 3).astype(np.float32))
        self.prior_depth = self._prior(scene.mono_depth, (V, HW))
        self.prior_normal = self._prior(scene.mono_normal, (V, HW, 3))
        self.prior_weight = torch.ones(V, HW)
        self.depth_fixed_scale = self.rays.scale if cfg.depth_fit == "metric" else None  # metric: the scene's metres per unit
        self.prior_loss_form = cfg.prior_loss_form
        self.prune_weight = cfg.prune_weight  # 0 = every sample with gradients (MonoSDF)
        self.pixel_sampler: PixelSampler = lambda v, n, g: torch.randint(0, HW, (n,), generator=g)  # noqa: E731
        self.extra_losses: list[Callable[..., dict[str, tuple[float, torch.Tensor]]]] = []
        self.diagnostic_sources: list[Callable[[], dict[str, float]]] = []  # their numbers join diagnostics() (MonoInstance's mask term)

        spec = make_grid_spec(cfg.grid_levels, cfg.grid_features, cfg.grid_log2_table, cfg.grid_base_res, cfg.grid_max_res) if cfg.use_grid else None
        self.sdf = SDFNetwork(spec, hidden=cfg.mlp_hidden, layers=cfg.mlp_layers, geo_features=cfg.geo_features,
                              radius=self.radius, init_radius=resolve_init_radius(cfg.init_radius, scene), inside_out=resolve_inside_out(cfg.inside_out, scene),
                              fast_grid=cfg.fast_grid, seed=seed, pe_frequencies=int(cfg.pe_frequencies),
                              skip=tuple(cfg.mlp_skip), weight_norm=cfg.weight_norm)
        self.color = ColorNetwork(cfg.geo_features, cfg.color_hidden, cfg.color_layers,
                                  appearance_dim=int(cfg.appearance_dim), num_images=V, view_dependent=cfg.color_view_dependent)
        self.density = LaplaceDensity(cfg.beta_init, cfg.beta_min)
        lr = float(cfg.lr)
        mlp_params = [p for n, p in self.sdf.named_parameters() if not n.startswith("grid.")]
        # three groups as MonoSDF's optimiser (encoding x grid_lr_factor, networks, density); the density
        # (beta) group at lr x beta_lr_factor (MonoSDF: 1)
        self.optim = torch.optim.Adam([
            {"params": [self.sdf.grid.table] if self.sdf.grid is not None else [], "lr": lr * cfg.grid_lr_factor},
            {"params": mlp_params + list(self.color.parameters()), "lr": lr},
            {"params": list(self.density.parameters()), "lr": lr * float(cfg.beta_lr_factor)},
        ], betas=(0.9, 0.99), eps=1e-15, fused=True)
        self.base_lrs = [g["lr"] for g in self.optim.param_groups]
        self.fixed_lr: float | None = None  # set: the network lr from now on (no decay), other groups at their factors
        self.step_count = 0
        self._log_sums: dict[str, float] = {}
        self._log_count = 0
        self._depth_scales: list[float] = []  # fitted depth scales since the last diagnostics()
        self._prunable_frac = 1.0  # fraction of the last step's samples with weight > prune_weight

    def _prior(self, arr: np.ndarray | None, shape: tuple[int, ...]) -> torch.Tensor | None:
        if arr is None:
            return None
        return torch.from_numpy(np.ascontiguousarray(arr[self.views]).reshape(shape).astype(np.float32))

    # ------------------------------------------------------------------ one step
    def render_pixels(self, view: int | torch.Tensor, pixels: torch.Tensor, jitter: bool = True, extra_points: torch.Tensor | None = None,
                      t: torch.Tensor | None = None, prune_weight: float = 0.0, coarse_sdf: torch.Tensor | None = None,
                      coarse: CoarseGradientPass | None = None) -> RenderOutput:
        """Render ``pixels`` (flat indices) of training view slot ``view`` (0..V-1; or an (R,) slot per ray)
        with that image's appearance code; ``extra_points`` (E, 3): also their SDF gradients
        (``RenderOutput.extra_grad``); ``t``: distances from :meth:`sample_rays` (None = sample here, unless
        ``coarse``: the sampler's coarse pass with gradients, :func:`render_rays`)."""
        r = self.rays
        if t is None and coarse is None:
            t = cast(torch.Tensor, self.sample_rays(r.origins[view].expand(len(pixels), 3), r.dirs[view, pixels], r.far[view, pixels], jitter))
        return render_rays(self.sdf, self.color, self.density, r.origins[view], r.dirs[view, pixels], r.z_factor[view, pixels],
                           r.far[view, pixels], r.world_to_cam_rot[view], self.cfg.near, self.cfg.n_coarse, self.cfg.n_fine,
                           self.gen, jitter, extra_points=extra_points, t=t, image=view, prune_weight=prune_weight,
                           coarse_sdf=coarse_sdf, coarse=coarse)

    @torch.no_grad()
    def sample_rays(self, origins: torch.Tensor, dirs: torch.Tensor, far: torch.Tensor, jitter: bool,
                    with_coarse_sdf: bool = False) -> torch.Tensor | tuple[torch.Tensor, torch.Tensor]:
        """Sample distances (R, S) along rays (origins, dirs: (R, 3); far: (R,)) with the configured sampler
        (``sampler``: hierarchical | error_bounded); ``with_coarse_sdf``: also the (R, S) SDF the sampler
        already evaluated there (NaN elsewhere). ``jitter``: training draws (False: deterministic)."""
        cfg = self.cfg
        gen = self.gen if jitter else None
        if cfg.sampler == "error_bounded":
            return error_bounded_samples(self.sdf, self.density, origins, dirs, far, cfg.near, cfg.eb_n_eval, cfg.eb_n_final,
                                         cfg.eb_n_extra, cfg.eb_eps, cfg.eb_beta_iters, cfg.eb_max_rounds, gen, jitter,
                                         with_coarse_sdf=with_coarse_sdf)
        return hierarchical_samples(self.sdf, self.density, origins, dirs, far, cfg.near, cfg.n_coarse, cfg.n_fine, gen, jitter,
                                    with_coarse_sdf=with_coarse_sdf)

    def _set_levels(self) -> None:
        """Coarse-to-fine grid (``grid_levels_initial`` < ``grid_levels``): start with that many levels and
        add one every ``grid_level_every`` (a fraction of the schedule)."""
        n0 = int(self.cfg.grid_levels_initial or self.cfg.grid_levels)
        every = float(self.cfg.grid_level_every)
        frac = self.step_count / max(int(self.cfg.iterations), 1)
        self.sdf.set_active_levels(n0 + (int(frac / every) if every > 0 else self.cfg.grid_levels))

    def _set_beta_floor(self) -> None:
        """``beta_floor``: beta >= beta_floor * (1 - t / beta_floor_until) + beta_min for the first
        ``beta_floor_until`` of the schedule (t = fraction done), then MonoSDF's beta_min: the surface
        stays soft while the objects are still to be carved out of free space (docs/studies/monosdf-stuck-mode-and-scale-bias.md)."""
        floor, until = float(self.cfg.beta_floor or 0.0), float(self.cfg.beta_floor_until or 0.0)
        frac = self.step_count / max(int(self.cfg.iterations), 1)
        extra = floor * max(0.0, 1.0 - frac / until) if floor > 0 and until > 0 else 0.0
        self.density.beta_min = float(self.cfg.beta_min) + extra

    def _set_lr(self) -> None:
        if self.fixed_lr is not None:  # a phase with its own learning rate (MonoInstance's code-only final phase)
            for g, base in zip(self.optim.param_groups, self.base_lrs):
                g["lr"] = base * self.fixed_lr / float(self.cfg.lr)  # every group keeps its factor to the network lr
            return
        frac = min(self.step_count / max(int(self.cfg.iterations), 1), 1.0)
        decay = float(self.cfg.lr_decay) ** frac * max(self._warmup("lr_warmup"), 1e-2)
        for g, base in zip(self.optim.param_groups, self.base_lrs):
            g["lr"] = base * decay

    def _warmup(self, key: str) -> float:
        """Linear ramp of a loss weight from 0 at step 0 to 1 at the config's ``key`` (a fraction of the
        schedule; 0 = full weight from the start, MonoSDF)."""
        frac = float(getattr(self.cfg, key))
        if frac <= 0:
            return 1.0
        return min(self.step_count / (frac * max(int(self.cfg.iterations), 1)), 1.0)

    def _per_image_terms(self, view: int, pixels: torch.Tensor, out: RenderOutput) -> dict[str, tuple[float, torch.Tensor]]:
        """The loss terms fitted per image on the rays ``pixels`` of slot ``view``: the scale-and-shift-
        invariant depth (one closed-form fit per image, never across images), the normal terms (L1,
        angular) and the ``extra_losses`` hooks (MonoInstance's mask constraint)."""
        cfg = self.cfg
        terms: dict[str, tuple[float, torch.Tensor]] = {}
        w = self.prior_weight[view, pixels]
        code_form = self.prior_loss_form == "code"
        if self.prior_depth is not None and cfg.depth_weight > 0:
            if code_form:
                crosses = (out.sdf.detach() > 0).any(-1) & (out.sdf.detach() < 0).any(-1)
                loss, scale = ssi_depth_fit_code(out.depth, self.prior_depth[view, pixels], w, crosses)
            else:
                loss, scale = ssi_depth_fit(out.depth, self.prior_depth[view, pixels], w, str(cfg.depth_negative_scale),
                                            fixed_scale=self.depth_fixed_scale)
            terms["depth"] = (float(cfg.depth_weight) * self._warmup("depth_warmup"), loss)
            self._depth_scales.append(float(scale))  # prior units per normalised unit (exact metric prior: the scene scale)
        if self.prior_normal is not None and cfg.normal_weight > 0:
            l1, ang = normal_loss(out.normal, self.prior_normal[view, pixels], w, reduce="rays" if code_form else "weighted")
            terms["normal_l1"] = (float(cfg.normal_weight), l1)
            terms["normal_cos"] = (float(cfg.normal_weight), ang)
        for extra in self.extra_losses:
            terms.update(extra(self, view, pixels, out))
        return terms

    def _ray_sample_regularisers(self, out: RenderOutput, g_extra: torch.Tensor, R: int, rows: torch.Tensor, pick: torch.Tensor | None,
                                 surf_in_extra: bool, mode: str, smooth_w: float) -> dict[str, tuple[float, torch.Tensor]]:
        """MonoSDF's eikonal (R uniform points + one sample of each ray) and smoothness (each with a jittered
        neighbour) terms; ``g_extra``: the SDF gradients of the extra points in :meth:`step`'s layout."""
        cfg = self.cfg
        terms: dict[str, tuple[float, torch.Tensor]] = {}
        g_uni = g_extra[:R]
        if surf_in_extra:
            g_surf, g_extra = g_extra[R : 2 * R], torch.cat([g_extra[:R], g_extra[2 * R :]])
        else:
            if pick is None:
                pick = out.weights.detach().argmax(-1)  # always rendered with gradients, also when pruned
            g_surf = out.grad[rows, pick]
        terms["eikonal"] = (float(cfg.eikonal_weight), eikonal_loss(torch.cat([g_uni, g_surf])))
        if smooth_w > 0:
            own = torch.cat([g_uni, g_surf]) if mode == "random" else g_uni  # random: the ray sample has a neighbour too
            terms["smooth"] = (smooth_w, smoothness_loss(own, g_extra[R:]))
        return terms

    def _all_sample_regularisers(self, out: RenderOutput, g_neighbours: torch.Tensor, smooth_w: float) -> dict[str, tuple[float, torch.Tensor]]:
        """The MonoInstance release's eikonal on every rendered ray sample and smoothness between each and its
        jittered neighbour (``g_neighbours``: (R * S, 3), or empty without smoothness); with pruning, over the
        samples rendered with gradients."""
        cfg = self.cfg
        g = out.grad.reshape(-1, 3)
        if out.kept_index is not None:
            g = g[out.kept_index]
            g_neighbours = g_neighbours[out.kept_index] if smooth_w > 0 else g_neighbours
        terms = {"eikonal": (float(cfg.eikonal_weight), eikonal_loss(g))}
        if smooth_w > 0:
            terms["smooth"] = (smooth_w, smoothness_loss(g, g_neighbours))
        return terms

    def step(self, view: int | None = None) -> dict[str, float]:
        """One optimisation step (:meth:`_step`), with float32 denormals flushed to 0 (FTZ / DAZ) while it runs when
        ``flush_denormals`` is on: arithmetic on denormals takes a slow microcode path, and a sharp field (softplus
        slopes sigmoid(100 z), the products of the backward) produces them; values change only below 1.2e-38
        (docs/studies/monosdf-speed.md). The mode is set in the OpenMP pool threads too (through the C++ extension:
        not with ``fast_grid: false``, which runs without C++) and reset to IEEE after the step
        (``float_mode.denormals_flushed``)."""
        with denormals_flushed(self.cfg.flush_denormals, pool_threads=self.cfg.fast_grid):  # fast_grid false: no C++ at all
            return self._step(view)

    def _step(self, view: int | None = None) -> dict[str, float]:
        """One optimisation step; returns the loss terms.

        ``rays_per_batch`` rays from ``images_per_batch`` distinct training images drawn at random
        (MonoSDF: one image per step; ``view`` forces the single slot ``view``). The colour and eikonal
        terms are means over all rays; the per-image terms (:meth:`_per_image_terms`) are computed per
        image and averaged over the images."""
        cfg = self.cfg
        self._set_levels()
        self._set_beta_floor()
        k = max(1, int(cfg.images_per_batch))
        if view is not None:
            views = [int(view)]
        elif k == 1:
            views = [int(torch.randint(0, len(self.views), (1,), generator=self.gen))]
        else:
            views = torch.randperm(len(self.views), generator=self.gen)[: min(k, len(self.views))].tolist()
        n_each = max(1, int(cfg.rays_per_batch) // len(views))
        groups = [(v, self.pixel_sampler(v, n_each, self.gen)) for v in views]
        slot = torch.cat([torch.full((len(p),), v, dtype=torch.long) for v, p in groups])
        pixels = torch.cat([p for _, p in groups])
        R = len(pixels)
        r = self.rays
        origins, dirs = r.origins[slot], r.dirs[slot, pixels]
        # prune only while the last step left enough weightless samples to pay for the no-gradient pass
        prune = self.prune_weight if self._prunable_frac <= PRUNE_WORTH else 0.0
        # the coarse samples evaluated once, with gradients, and rendered from that pass (coarse_gradient_pass); a pruning
        # step evaluates them without gradients instead (most are pruned)
        coarse: CoarseGradientPass | None = None
        coarse_sdf: torch.Tensor | None = None  # the sampler's SDF, reused by the pruning pass
        with record_function("step.sampler"):  # phase labels: what torch.profiler shows per phase (no cost without a profiler)
            if cfg.coarse_gradient_pass and cfg.sampler == "hierarchical" and prune == 0:
                coarse = hierarchical_samples_with_gradient(self.sdf, self.density, origins, dirs, r.far[slot, pixels], cfg.near,
                                                            cfg.n_coarse, cfg.n_fine, self.gen, True)
                t = coarse.t
            elif prune > 0:
                t, coarse_sdf = cast("tuple[torch.Tensor, torch.Tensor]",
                                     self.sample_rays(origins, dirs, r.far[slot, pixels], True, with_coarse_sdf=True))
            else:
                t = cast(torch.Tensor, self.sample_rays(origins, dirs, r.far[slot, pixels], True))
        # eikonal points (MonoSDF): R uniform points in the bounding cube + one sample of each ray
        # (``eikonal_ray_sample``: "random" = MonoSDF, "max_weight" = the highest-weight sample; the ray
        # sample's gradient comes from the rendering itself); with ``smooth_weight`` > 0 also a neighbour of
        # each, jittered by U(-smooth_jitter/2, smooth_jitter/2) per axis (MonoSDF / UNISURF: 0.01). All
        # extra points ride in the rendering's SDF pass.
        uni = (torch.rand(R, 3, generator=self.gen) * 2 - 1) * self.radius
        rows = torch.arange(R)
        mode = cfg.eikonal_ray_sample  # random | max_weight | all (checked by MonoSDFConfig)
        smooth_w = float(cfg.smooth_weight)
        jit = float(cfg.smooth_jitter)
        pick = torch.randint(0, t.shape[1], (R,), generator=self.gen) if mode == "random" else None
        extra = [uni]
        surf = None if pick is None else origins + dirs * t[rows, pick][:, None]  # the random ray sample (R, 3)
        # a pruned rendering has no gradient at most samples: the random ray sample then rides with the extras
        surf_in_extra = surf is not None and prune > 0
        if surf_in_extra:
            extra.append(cast(torch.Tensor, surf))  # surf_in_extra implies surf is not None
        if mode == "all":  # the release: every ray sample and a jittered neighbour of each, no uniform points
            extra = [torch.zeros(0, 3)]
            if smooth_w > 0:
                samples = (origins[:, None, :] + dirs[:, None, :] * t[..., None]).reshape(-1, 3)
                extra.append(samples + (torch.rand(samples.shape, generator=self.gen) - 0.5) * jit)
        elif smooth_w > 0:
            extra.append(uni + (torch.rand(R, 3, generator=self.gen) - 0.5) * jit)
            if surf is not None:
                extra.append(surf + (torch.rand(R, 3, generator=self.gen) - 0.5) * jit)
        single = len(views) == 1
        with record_function("step.render"):
            out = self.render_pixels(views[0] if single else slot, pixels, extra_points=torch.cat(extra),
                                     t=None if coarse is not None else t, prune_weight=prune, coarse_sdf=coarse_sdf, coarse=coarse)
        terms: dict[str, tuple[float, torch.Tensor]] = {"color": (float(cfg.color_weight), color_loss(out.rgb, self.rgb[slot, pixels]))}
        g_extra = out.extra_grad
        assert g_extra is not None
        if mode == "all":
            terms.update(self._all_sample_regularisers(out, g_extra, smooth_w))
        else:
            terms.update(self._ray_sample_regularisers(out, g_extra, R, rows, pick, surf_in_extra, mode, smooth_w))
        per_image: dict[str, list[tuple[float, torch.Tensor]]] = {}
        start = 0
        for v, pix in groups:
            o = out if single else out.select(slice(start, start + len(pix)))
            start += len(pix)
            for name, term in self._per_image_terms(v, pix, o).items():
                per_image.setdefault(name, []).append(term)
        for name, items in per_image.items():
            terms[name] = (items[0][0], torch.stack([val for _, val in items]).mean())

        loss = cast(torch.Tensor, sum(wt * val for wt, val in terms.values()))  # terms has "color": never the 0 start
        self._set_lr()
        self.optim.zero_grad(set_to_none=True)
        with record_function("step.backward"):
            loss.backward()
        with record_function("step.optimizer"):
            self.optim.step()
        self.step_count += 1
        logs = {k: float(v.detach()) for k, (_, v) in terms.items()}
        logs["loss"] = float(loss.detach())
        logs["beta"] = float(self.density.beta().detach())
        if self.prune_weight > 0:
            self._prunable_frac = float((out.weights.detach() > self.prune_weight).float().mean())
        stats = {"samples_weighted": float((out.weights.detach() > WEIGHTED_SAMPLE).sum(-1).float().mean()),
                 "samples_rendered": out.kept / R}  # per ray, with gradients (cfg.samples_per_ray() unless pruned)
        total = abs(logs["loss"])
        for name, (wt, _) in terms.items():  # each weighted term's share of the total loss
            stats[f"share_{name}"] = wt * logs[name] / total if total > 0 else 0.0
        for name, value in {**logs, **stats}.items():
            self._log_sums[name] = self._log_sums.get(name, 0.0) + value
        self._log_count += 1
        return logs

    def diagnostics(self, mesh: trimesh.Trimesh | None = None) -> dict[str, float]:
        """Numbers for the convergence study at a snapshot: ``beta``; ``loss_<term>``, each loss term
        averaged over the steps since the previous call (then reset), and ``share_<term>``, its weighted share
        of the total loss (same average); the numbers of every :attr:`diagnostic_sources` callable; ``depth_neg_scale_frac``, the fraction
        of the per-image depth fits since then whose scale was <= 0 (rendered depth anti-correlated with the
        prior), and ``depth_fit_scale_median``, their median scale (prior units per normalised unit: with an
        exact metric prior the scene's metres per unit, so another value is a scaled geometry); with ``diag_views`` > 0 and GT depth,
        ``depth_err_median`` / ``depth_err_p90``: median / 90th percentile of |rendered z-depth - GT| (m)
        over that many evenly spaced training views at every ``diag_stride``-th pixel where GT > 0; with a
        ``mesh`` (world metres) also ``mesh_depth_err_median`` (the mesh ray-cast at the same pixels
        against GT) and ``mesh_ahead_frac``: the fraction of those pixels where the mesh surface lies more
        than 10 cm in front of the volume-rendered depth (surfaces the rendering does not weigh);
        ``sampler_gap_median`` / ``sampler_gap_p90``: |depth with the training sampler - depth with 8x the
        coarse samples| (m), how far the sampler's depth is from what a dense sampling of the same field gives;
        ``samples_weighted``: rendered samples per ray whose weight exceeds :data:`WEIGHTED_SAMPLE` (the
        rest cost as much and carry almost nothing: the room a narrow-band sampler has); ``edge_px_frac`` (pixels within 1 px of a GT depth jump, :func:`depth_edges`) and the error split into
        ``depth_err_edge_median`` / ``depth_err_interior_median`` / ``depth_err_interior_p90`` (a blur across
        occlusion edges vs a surface in the wrong place); ``depth_fit_scale_iqr``: interquartile range of the
        per-batch fitted scales."""
        out = {"beta": float(self.density.beta().detach())}
        n = max(self._log_count, 1)
        out.update({(k if k.startswith(("samples_", "share_")) else f"loss_{k}"): v / n for k, v in self._log_sums.items() if k != "beta"})
        for source in self.diagnostic_sources:
            out.update(source())
        if self._depth_scales:
            out["depth_neg_scale_frac"] = float(np.mean(np.asarray(self._depth_scales) <= 0))
            out["depth_fit_scale_median"] = float(np.median(self._depth_scales))
            q1, q3 = np.percentile(self._depth_scales, [25, 75])
            out["depth_fit_scale_iqr"] = float(q3 - q1)  # spread of the per-batch fits: a consistent geometry fits one scale
        self._log_sums, self._log_count, self._depth_scales = {}, 0, []
        k = int(self.cfg.diag_views)
        if k > 0 and self.scene.gt_depth is not None:
            stride = int(self.cfg.diag_stride)
            errs, edge_flags, mesh_errs, ahead, gaps = [], [], [], [], []
            slots = np.unique(np.linspace(0, len(self.views) - 1, k).round().astype(int))
            mesh_depth = None
            if mesh is not None and len(mesh.faces):
                from metrics.render import render_depth_maps

                v = self.views[slots]
                mesh_depth = render_depth_maps(mesh, self.scene.intrinsics[v], self.scene.cam_to_world[v], self.scene.height, self.scene.width)
            for i, slot in enumerate(slots):
                gt = self.scene.gt_depth[self.views[slot]][::stride, ::stride]
                pred = self.render_view_depth(int(slot), stride=stride)
                errs.append(np.abs(pred - gt)[gt > 0])
                edge_flags.append(depth_edges(self.scene.gt_depth[self.views[slot]])[::stride, ::stride][gt > 0])
                dense = self.render_view_depth(int(slot), stride=stride, n_coarse=8 * int(self.cfg.n_coarse))
                gaps.append(np.abs(pred - dense)[gt > 0])
                if mesh_depth is not None:
                    md = mesh_depth[i][::stride, ::stride]
                    hit = (gt > 0) & (md > 0)
                    mesh_errs.append(np.abs(md - gt)[hit])
                    ahead.append((hit & (md < pred - 0.10))[gt > 0])
            e = np.concatenate(errs) if errs else np.zeros(0)
            if len(e):
                out["depth_err_median"] = float(np.median(e))
                out["depth_err_p90"] = float(np.percentile(e, 90))
                edge = np.concatenate(edge_flags)
                out["edge_px_frac"] = float(edge.mean())
                if (~edge).any():
                    out["depth_err_interior_median"] = float(np.median(e[~edge]))
                    out["depth_err_interior_p90"] = float(np.percentile(e[~edge], 90))
                if edge.any():
                    out["depth_err_edge_median"] = float(np.median(e[edge]))
                g = np.concatenate(gaps)
                out["sampler_gap_median"] = float(np.median(g))
                out["sampler_gap_p90"] = float(np.percentile(g, 90))
            if mesh_errs and len(np.concatenate(mesh_errs)):
                out["mesh_depth_err_median"] = float(np.median(np.concatenate(mesh_errs)))
                out["mesh_ahead_frac"] = float(np.concatenate(ahead).mean())
        return out

    # ------------------------------------------------------------------ outputs
    @torch.no_grad()
    def sdf_on_grid(self, resolution: int, chunk: int = 262144) -> tuple[np.ndarray, np.ndarray, float]:
        """SDF on a resolution^3 grid over the cube [-E, E]^3 -> (values (n, n, n), origin (3,), spacing).

        E = ``mesh_extent`` (normalised units) when set, else the bounding-sphere radius R: an object
        scene whose sphere also holds the cameras extracts only around the object (cells of 2E/n)."""
        n = int(resolution)
        extent = self.radius if self.cfg.mesh_extent is None else min(float(self.cfg.mesh_extent), self.radius)
        lin = torch.linspace(-extent, extent, n)
        vals = torch.empty(n, n, n)
        for i in range(n):
            xx, yy = torch.meshgrid(lin, lin, indexing="ij")
            pts = torch.stack([torch.full_like(xx, float(lin[i])), xx, yy], -1).reshape(-1, 3)
            out = [self.sdf(pts[s : s + chunk], with_gradient=False)[0] for s in range(0, len(pts), chunk)]
            vals[i] = torch.cat(out).reshape(n, n)
        return vals.numpy(), np.full(3, -extent), float(2 * extent / (n - 1))

    def extract_mesh(self, resolution: int) -> trimesh.Trimesh:
        """Marching cubes (scikit-image) of the zero level set, in WORLD metres."""
        from skimage.measure import marching_cubes

        vals, origin, spacing = self.sdf_on_grid(resolution)
        if not (vals.min() < 0 < vals.max()):
            return trimesh.Trimesh(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64), process=False)
        verts, faces, _, _ = marching_cubes(vals, level=0.0, spacing=(spacing,) * 3)
        verts = verts + origin
        centre, scale = normalisation(self.scene)
        return trimesh.Trimesh(verts * scale + centre, faces[:, ::-1].copy(), process=False)

    @torch.no_grad()
    def render_view_depth(self, view: int, stride: int = 1, chunk: int = 4096, n_coarse: int | None = None) -> np.ndarray:
        """z-depth in metres of training slot ``view`` at every ``stride``-th pixel -> (ceil(H/stride), ceil(W/stride));
        ``n_coarse`` overrides the sampler's coarse samples (a denser reference for the diagnostics: always the
        hierarchical sampler with 8x its coarse samples); None = the configured sampler."""
        H, W = self.scene.height, self.scene.width
        rows, cols = np.arange(0, H, stride), np.arange(0, W, stride)
        pix = torch.from_numpy((rows[:, None] * W + cols[None, :]).reshape(-1))
        r, depth = self.rays, []
        for s in range(0, len(pix), chunk):
            p = pix[s : s + chunk]
            t = None if n_coarse is not None else cast(
                torch.Tensor, self.sample_rays(r.origins[view].expand(len(p), 3), r.dirs[view, p], r.far[view, p], False))
            depth.append(render_depth(self.sdf, self.density, r.origins[view], r.dirs[view, p], r.z_factor[view, p], r.far[view, p],
                                      self.cfg.near, int(n_coarse or self.cfg.n_coarse), self.cfg.n_fine, t=t))
        return (torch.cat(depth) * r.scale).reshape(len(rows), len(cols)).numpy()

    # ------------------------------------------------------------------ checkpoints
    def state_dict(self) -> dict[str, Any]:
        """Everything the following steps and the next :meth:`diagnostics` depend on: loaded into a trainer built
        with the same scene, config and seed, training continues exactly as it would have (the stage cache,
        ``methods.stage_cache``, relies on it). The ray / pixel sampler state (MonoInstance's stage 2) is not in it."""
        return {"sdf": self.sdf.state_dict(), "color": self.color.state_dict(), "density": self.density.state_dict(),
                "optim": self.optim.state_dict(), "step": self.step_count, "gen": self.gen.get_state(), "cfg": config_record(self.cfg),
                "seed": self.seed, "torch_rng": torch.get_rng_state(), "prunable_frac": self._prunable_frac,
                "log": {"sums": dict(self._log_sums), "count": self._log_count, "depth_scales": list(self._depth_scales)}}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore :meth:`state_dict` (older checkpoints lack the global RNG, the pruning
        fraction and the diagnostics' running sums: those keep their current values)."""
        self.sdf.load_state_dict(state["sdf"])
        self.color.load_state_dict(state["color"])
        self.density.load_state_dict(state["density"])
        self.optim.load_state_dict(state["optim"])
        self.step_count = int(state["step"])
        self.gen.set_state(state["gen"])
        if "torch_rng" in state:
            torch.set_rng_state(state["torch_rng"])
        self._prunable_frac = float(state.get("prunable_frac", self._prunable_frac))
        if "log" in state:
            log = state["log"]
            self._log_sums, self._log_count, self._depth_scales = dict(log["sums"]), int(log["count"]), list(log["depth_scales"])

    def save(self, path: str | Path) -> None:
        """Write a checkpoint atomically."""
        import io

        from bench.data.atomic import atomic_write_bytes

        buf = io.BytesIO()
        torch.save(self.state_dict(), buf)
        atomic_write_bytes(path, buf.getvalue())

    def load(self, path: str | Path) -> None:
        self.load_state_dict(torch.load(path, weights_only=False))


def snapshot_steps(iterations: int, fractions: list[float]) -> list[int]:
    """The step counts at which :func:`train_with_snapshots` extracts a mesh: each fraction of ``iterations``,
    rounded, at least 1, sorted, without repeats."""
    return sorted({max(1, int(round(f * iterations))) for f in fractions})


def train_with_snapshots(
    trainer: MonoSDFTrainer,
    iterations: int,
    fractions: list[float],
    mesh_resolution: int,
    progress: Callable[[float, str], None] | None = None,
    start_seconds: float = 0.0,
    events: dict[int, Callable[[], None]] | None = None,
) -> tuple[list[Snapshot], float, float]:
    """Run ``trainer`` up to ``iterations`` steps, extracting a mesh at each fraction of the schedule.

    Args:
        events: ``{step: callback}`` run when the step count reaches ``step`` (before the snapshot of
            that step, if any): MonoInstance's between-stage work and phase switches. Their wall time
            counts towards the snapshots' seconds, not towards the returned train seconds.

    Every time is wall time minus the C++ kernel builds inside it (:class:`methods.cpp_build.OwnClock`):
    a first step that waited for a compile books its own work only.

    Returns:
        (snapshots; seconds = start_seconds + training + events so far + this snapshot's mesh extraction,
        earlier extractions excluded; each with :meth:`MonoSDFTrainer.diagnostics`, whose own time is not
        counted), train seconds, mesh seconds of the last snapshot.
    """
    events = dict(events or {})
    marks = snapshot_steps(iterations, fractions)
    snaps: list[Snapshot] = []
    train_s = event_s = mesh_s = 0.0
    for stop in sorted(set(marks) | {k for k in events if 0 <= k <= iterations}):
        clock = OwnClock()
        while trainer.step_count < stop:
            logs = trainer.step()
            if progress and trainer.step_count % 25 == 0:
                progress(trainer.step_count / iterations, f"step {trainer.step_count}/{iterations} loss {logs['loss']:.4f} beta {logs['beta']:.4f}")
        train_s += clock.seconds()
        if stop in events:
            clock = OwnClock()
            events[stop]()
            event_s += clock.seconds()
        if stop in marks:
            clock = OwnClock()
            mesh = trainer.extract_mesh(mesh_resolution)
            mesh_s = clock.seconds()
            snaps.append(Snapshot(stop / iterations, trainer.step_count, start_seconds + train_s + event_s + mesh_s, mesh=mesh,
                                  diagnostics=trainer.diagnostics(mesh)))
    return snaps, train_s, mesh_s
