"""The registered ``monosdf`` method: MonoSDF (grid variant) scaled down for a CPU.

Config: ``configs/methods/monosdf.yaml``. The no-prior ablation of Table 1 is this method with
``depth_weight: 0, normal_weight: 0`` (a config, not a copy).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from bench.data.config import load_config
from bench.data.scene import Scene
from methods.base import Artifacts, ProgressFn
from methods.cpp_build import OwnClock
from methods.monosdf.config import MonoSDFConfig
from methods.monosdf.trainer import MonoSDFTrainer, train_with_snapshots
from methods.registry import register


def set_threads(threads: int) -> None:
    """Torch intra-op threads (0 = leave torch's default)."""
    import torch

    if threads > 0:
        torch.set_num_threads(threads)


@register("monosdf")
class MonoSDF:
    """MonoSDF: VolSDF + monocular depth / normal priors (uniform weights, uniform ray sampling)."""

    name = "monosdf"
    config_type = MonoSDFConfig

    def fit(self, scene: Scene, config: Mapping[str, Any], seed: int, progress: ProgressFn | None = None) -> Artifacts:
        cfg = load_config(MonoSDFConfig, config, f"{self.name} config")
        set_threads(cfg.threads)
        clock = OwnClock()
        trainer = MonoSDFTrainer(scene, cfg, seed)
        setup_s = clock.seconds()
        snaps, train_s, mesh_s = train_with_snapshots(trainer, cfg.iterations, list(cfg.fractions),
                                                      cfg.mesh_resolution, progress, start_seconds=setup_s)
        return Artifacts(
            snapshots=snaps,
            timings={"setup": setup_s, "train": train_s, "mesh": mesh_s},
            iterations=trainer.step_count,
            extra={"beta": float(trainer.density.beta().detach()), "samples_per_ray": cfg.samples_per_ray()},
        )
