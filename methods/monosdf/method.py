"""The registered ``monosdf`` method: MonoSDF (grid variant) scaled down for a CPU.

Config: ``configs/methods/monosdf.yaml``. The no-prior ablation of Table 1 is this method with
``depth_weight: 0, normal_weight: 0`` (a config, not a copy).
"""

from __future__ import annotations

import time
from typing import Any

from bench.data.scene import Scene
from methods.base import Artifacts, ProgressFn
from methods.monosdf.trainer import MonoSDFTrainer, train_with_snapshots
from methods.registry import register


def set_threads(cfg: dict[str, Any]) -> None:
    """Torch intra-op threads from the config (0 = leave torch's default)."""
    import torch

    if int(cfg.get("threads", 0)) > 0:
        torch.set_num_threads(int(cfg["threads"]))


@register("monosdf")
class MonoSDF:
    """MonoSDF: VolSDF + monocular depth / normal priors (uniform weights, uniform ray sampling)."""

    name = "monosdf"

    def fit(self, scene: Scene, config: dict[str, Any], seed: int, progress: ProgressFn | None = None) -> Artifacts:
        set_threads(config)
        t0 = time.perf_counter()
        trainer = MonoSDFTrainer(scene, config, seed)
        setup_s = time.perf_counter() - t0
        snaps, train_s, mesh_s = train_with_snapshots(trainer, int(config["iterations"]), list(config["fractions"]),
                                                      int(config["mesh_resolution"]), progress, start_seconds=setup_s)
        return Artifacts(
            snapshots=snaps,
            timings={"setup": setup_s, "train": train_s, "mesh": mesh_s},
            iterations=trainer.step_count,
            extra={"beta": float(trainer.density.beta().detach()), "samples_per_ray": int(config["n_coarse"]) + int(config["n_fine"])},
        )
