"""MonoInstance's uncertainty stage, shared by the MonoInstance SDF and Gaussian-splatting methods.

Pipeline (docs/uncertainty.md): per-view alignment of the mono depth prior to a reference depth
(:func:`align_mono_depth`), multi-view consistent instances (:func:`associate_instances`), and the
density-based uncertainty U = 1 - c (:func:`estimate_uncertainty`); :func:`run_uncertainty_stage` runs
all three on a :class:`bench.data.scene.Scene`. Defaults: ``configs/methods/monoinstance_uncertainty.yaml``.
"""

from methods.monoinstance.alignment import align_mono_depth, align_mono_depth_status
from methods.monoinstance.association import Association, associate_instances
from methods.monoinstance.config import MonoInstanceConfig, UncertaintyStageConfig, load_stage_config, stage_defaults
from methods.monoinstance.quality import adjusted_rand_index, purity
from methods.monoinstance.stage import (
    UncertaintyResult,
    run_uncertainty_stage,
    save_uncertainty_maps,
    split_stage_config,
    stage_quality,
)
from methods.monoinstance.uncertainty import InstanceUncertainty, certainty_from_densities, estimate_uncertainty

__all__ = [
    "Association",
    "InstanceUncertainty",
    "UncertaintyResult",
    "adjusted_rand_index",
    "align_mono_depth",
    "align_mono_depth_status",
    "associate_instances",
    "certainty_from_densities",
    "estimate_uncertainty",
    "MonoInstanceConfig",
    "UncertaintyStageConfig",
    "load_stage_config",
    "purity",
    "run_uncertainty_stage",
    "save_uncertainty_maps",
    "split_stage_config",
    "stage_defaults",
    "stage_quality",
]
