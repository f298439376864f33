"""The registered ``monoinstance`` method: MonoInstance on the MonoSDF base (paper Sec. 3.4, official schedule).

Stage 1 (``stage1_fraction`` = 1/4 of the iterations): plain MonoSDF (uniform prior weights, uniform
rays). Between the stages: render every training view's depth at 1/``ref_depth_downscale`` resolution,
run the shared uncertainty stage (``methods.monoinstance.stage``: alignment, multi-view consistent
instances, density uncertainty). Stage 2: the modules switched on by config -

* ``uncertainty``: adaptive depth / normal loss, per-ray weight c = 1 - U, instance rays with
  c < ``certainty_cutoff`` (0.2, code) set to 0;
* ``guided_sampling``: :class:`methods.monoinstance.sampling.GuidedSampler`;
* ``mask_constraint``: :class:`methods.monoinstance.mask_constraint.MaskConstraint` (weight 0.4).

With all three off this is exactly MonoSDF (no stage in between): the ablation's Base row. The four
rows of Table 4 are configs of this one method. Optional code-only final phase
(``final_phase_fraction``): mask constraint off, depth weight 0.1, normal weight 0.005, network lr 1e-5
(``final_phase_depth_weight`` / ``final_phase_normal_weight`` / ``final_phase_lr``).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

import numpy as np
import torch

from bench.data.config import load_config
from bench.data.scene import Scene
from methods.base import Artifacts, ProgressFn
from methods.cpp_build import OwnClock
from methods.monoinstance.config import MonoInstanceConfig
from methods.monoinstance.mask_constraint import MaskConstraint
from methods.monoinstance.sampling import GuidedSampler
from methods.monoinstance.stage import run_uncertainty_stage
from methods.monosdf.config import MonoSDFConfig
from methods.monosdf.method import set_threads
from methods.monosdf.trainer import MonoSDFTrainer, snapshot_steps, train_with_snapshots
from methods.registry import register
from methods.stage_cache import checkpoint_dir, load_stage, save_stage, stage_key, tensor_digest


def certainty_weights(uncertainty: np.ndarray, instance_ids: np.ndarray, is_background: dict[int, bool], cutoff: float) -> np.ndarray:
    """Per-pixel prior weights c = 1 - U; foreground-instance pixels with c < cutoff -> 0 (code). (V, H, W)."""
    c = 1.0 - uncertainty.astype(np.float32)
    fg = np.zeros(instance_ids.shape, dtype=bool)
    for k in np.unique(instance_ids):
        if k != 0 and not is_background.get(int(k), False):
            fg |= instance_ids == k
    c[fg & (c < cutoff)] = 0.0
    return c


def _chain(*fns):
    """One event callback running ``fns`` in order."""
    return lambda: [f() for f in fns]


def stage1_key(trainer: MonoSDFTrainer, cfg: MonoInstanceConfig, seed: int, stage1_end: int, final_start: int) -> str | None:
    """Key of this job's stage-1 end state in the stage cache (``methods.stage_cache``), or None when it cannot be
    shared: no cache folder (a direct ``fit``), a snapshot before the end of stage 1 (its mesh would be missing), a
    final phase starting inside stage 1, or no stage 2. Stage 1 is plain MonoSDF whatever the modules: the key holds
    every MonoSDF key of the config (none of MonoInstance's own), the seed, the training data's bytes and the thread
    count, and through ``stage_key`` the matrix-product path the harness passes (both round differently) and the code."""
    first_snapshot = snapshot_steps(cfg.iterations, list(cfg.fractions))[0]
    if checkpoint_dir() is None or first_snapshot < stage1_end or final_start <= stage1_end or stage1_end >= cfg.iterations:
        return None
    rays = trainer.rays
    data = tensor_digest(trainer.rgb, trainer.prior_depth, trainer.prior_normal, trainer.prior_weight, rays.origins, rays.dirs,
                         rays.z_factor, rays.far, rays.world_to_cam_rot)
    monosdf_keys = {f.name: getattr(cfg, f.name) for f in dataclasses.fields(MonoSDFConfig)}
    return stage_key({"stage": "monoinstance.stage1", "end": stage1_end, "config": monosdf_keys, "seed": seed, "data": data,
                      "scale": rays.scale, "threads": torch.get_num_threads()})


@register("monoinstance")
class MonoInstance:
    """MonoSDF + MonoInstance's uncertainty modules (each switchable by config)."""

    name = "monoinstance"
    config_type = MonoInstanceConfig

    def fit(self, scene: Scene, config: Mapping[str, Any], seed: int, progress: ProgressFn | None = None) -> Artifacts:
        cfg = load_config(MonoInstanceConfig, config, f"{self.name} config")
        set_threads(cfg.threads)
        setup_clock = OwnClock()
        trainer = MonoSDFTrainer(scene, cfg, seed)
        timings = {"setup": setup_clock.seconds()}
        total = cfg.iterations
        extra: dict[str, Any] = {}
        stage: dict[str, np.ndarray] = {}
        events = {}
        stage1_end = max(1, int(round(cfg.stage1_fraction * total)))
        final_start = total - int(round(cfg.final_phase_fraction * total))
        if cfg.modules_on:
            events[stage1_end] = lambda: stage.update(U=self._between_stages(trainer, scene, cfg, seed, timings, extra))
            if final_start < total:  # code-only final phase: no mask constraint, its own depth / normal weights and lr
                def final_phase() -> None:
                    trainer.extra_losses.clear()
                    trainer.cfg = dataclasses.replace(trainer.cfg, depth_weight=cfg.final_phase_depth_weight,
                                                      normal_weight=cfg.final_phase_normal_weight)
                    if cfg.final_phase_lr is not None:
                        trainer.fixed_lr = cfg.final_phase_lr

                events[max(final_start, stage1_end)] = final_phase if final_start > stage1_end else _chain(events[stage1_end], final_phase)
        shared_s = 0.0  # seconds of stage 1 loaded from the stage cache instead of trained here
        key = stage1_key(trainer, cfg, seed, stage1_end, final_start) if cfg.share_stage1 else None
        state = None if key is None else load_stage(key)
        if state is not None:
            trainer.load_state_dict(state["trainer"])
            shared_s = float(state["train_seconds"])
            timings["train_shared"] = shared_s
            if progress:
                progress(stage1_end / total, f"stage 1 loaded from the stage cache ({shared_s:.0f} s of training not repeated)")
        elif key is not None:  # train stage 1 here and store it for the other rows, before the between-stages work runs
            train_clock = OwnClock()  # the stage's own training: a wait for a kernel build is not booked

            def store() -> None:
                save_stage(key, {"trainer": trainer.state_dict(), "train_seconds": train_clock.seconds()})

            events[stage1_end] = _chain(store, events[stage1_end]) if stage1_end in events else store
        snapshots, train_s, mesh_s = train_with_snapshots(trainer, total, list(cfg.fractions), cfg.mesh_resolution,
                                                          progress, start_seconds=timings["setup"] + shared_s, events=events)
        timings.update(train=train_s + shared_s, mesh=mesh_s)
        uncertainty = stage.get("U")
        extra["beta"] = float(trainer.density.beta().detach())
        full_u = None
        if uncertainty is not None:
            full_u = np.zeros((scene.num_views, scene.height, scene.width), dtype=np.float32)
            full_u[trainer.views] = uncertainty
        return Artifacts(snapshots=snapshots, timings=timings, iterations=trainer.step_count, uncertainty=full_u, extra=extra)

    @staticmethod
    def _between_stages(trainer: MonoSDFTrainer, scene: Scene, cfg: MonoInstanceConfig, seed: int,
                        timings: dict[str, float], extra: dict[str, Any]) -> np.ndarray:
        """Render the reference depth, run the uncertainty stage, switch on the stage-2 modules."""
        stage_cfg = cfg.stage
        f = stage_cfg.ref_depth_downscale
        clock = OwnClock()
        ref = np.zeros((scene.num_views, -(-scene.height // f), -(-scene.width // f)), dtype=np.float32)
        for slot, v in enumerate(trainer.views):
            ref[v] = trainer.render_view_depth(slot, stride=f)
        timings["render_ref_depth"] = clock.seconds()
        result = run_uncertainty_stage(scene, ref, stage_cfg, rng_seed=seed, quality=scene.gt_depth is not None)
        timings["segmentation"] = float(result.timings.get("segmentation", 0.0))
        timings["uncertainty"] = float(result.timings.get("align", 0.0) + result.timings.get("uncertainty", 0.0))
        extra.update({k: float(v) for k, v in result.quality.items() if isinstance(v, (int, float))})
        views = trainer.views
        U = result.uncertainty[views]
        ids = result.instance_ids[views]
        c = certainty_weights(U, ids, result.is_background, cfg.certainty_cutoff)
        if cfg.uncertainty:
            trainer.prior_weight = torch.from_numpy(c.reshape(len(views), -1))
        if cfg.guided_sampling:
            trainer.pixel_sampler = GuidedSampler(ids, result.is_background, U, prob_offset=cfg.sampling_prob_offset)
        if cfg.mask_constraint:
            mask_term = MaskConstraint(trainer, ids, result.is_background, c <= 0, cfg)
            trainer.extra_losses.append(mask_term)
            trainer.diagnostic_sources.append(mask_term.diagnostics)
        return U
