"""Typed configs of MonoInstance: the uncertainty stage (shared by the SDF and the Gaussian methods) and
the ``monoinstance`` SDF method.

Names and types only. The values live in one place each:

* the uncertainty stage: ``configs/methods/monoinstance_uncertainty.yaml`` (a flat mapping, not a
  method config; a method passes overrides of it: ``uncertainty_stage`` / ``uncertainty_config``);
* the method: ``configs/methods/monoinstance.yaml`` (``base: monosdf``: every MonoSDF key plus the
  keys below).

Units of the stage (docs/uncertainty.md): lengths of the density step are in the code's NORMALISED
scene units (x ``scene_radius`` = metres); association lengths are in metres.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Annotated, Any, Literal

import yaml

from bench.data.config import AtLeastOne, Fraction, NonNegative, Positive, Range, load_config
from bench.data.errors import BenchInputError
from methods.monosdf.config import MonoSDFConfig

STAGE_CONFIG_PATH = Path(__file__).resolve().parents[2] / "configs" / "methods" / "monoinstance_uncertainty.yaml"
Degrees = Range(lo=0, hi=180)


@dataclass(frozen=True)
class UncertaintyStageConfig:
    """Every parameter of the uncertainty stage; documented in ``configs/methods/monoinstance_uncertainty.yaml``."""

    # step 1: alignment of the mono depth prior to the reference (stage-1 rendered) depth
    align_mode: Literal["scale", "scale_shift"]
    align_border_px: Annotated[int, NonNegative]
    align_min_pixels: Annotated[int, AtLeastOne]
    ref_depth_downscale: Annotated[int, AtLeastOne]
    nonfinite_depth: Literal["mask", "raise"]
    # multi-view consistent segmentation (metres)
    assoc_min_pixels: Annotated[int, NonNegative]
    assoc_max_points: Annotated[int, AtLeastOne]
    assoc_max_target_points: Annotated[int, AtLeastOne]
    assoc_chamfer_m: Annotated[float, Positive]
    assoc_chamfer_relative: Annotated[float, Positive] | None
    assoc_chamfer_mode: Literal["min", "symmetric"]
    assoc_overlap_radius_m: Annotated[float, Positive]
    assoc_overlap_min: Annotated[float, Fraction]
    assoc_cluster: Literal["greedy", "louvain", "components", "given"]
    assoc_seed: int
    assoc_louvain_resolution: Annotated[float, Positive]
    assoc_background: Literal["associate", "mark"]
    # density-based uncertainty (normalised units unless stated)
    n_subsample: Annotated[int, AtLeastOne]
    dbscan_eps: Annotated[float, Positive]
    dbscan_min_points: Annotated[int, AtLeastOne]
    dbscan_min_cluster_frac: Annotated[float, Fraction]
    drop_dbscan_noise: bool
    sor_nb_neighbors: Annotated[int, AtLeastOne]
    sor_std_ratio: Annotated[float, Positive]
    obb_method: Literal["pca", "minimal"]
    radius_offset: Annotated[float, NonNegative]
    use_radius_clamp: bool
    radius_clamp: tuple[Annotated[float, Positive], Annotated[float, Positive]]
    density_cap: Annotated[int, AtLeastOne]
    density_ref_points: Annotated[int, AtLeastOne] | None
    max_density_frac: Annotated[float, Range(lo=0, hi=1, lo_open=True)]
    min_views_per_instance: Annotated[int, AtLeastOne]
    min_instance_points: Annotated[int, AtLeastOne]
    failed_instance_u: Annotated[float, Fraction]
    scene_radius: Annotated[float, Positive] | None  # metres per normalised unit; None = from Scene.scale_mat

    def check(self) -> str | None:
        lo, hi = self.radius_clamp
        if lo > hi:
            return f"radius_clamp must be [low, high] with low <= high, got {list(self.radius_clamp)}"
        return None

    def with_scene_radius(self, radius_m: float) -> UncertaintyStageConfig:
        """The same config with ``scene_radius`` set (the stage fills it from the scene when null)."""
        return replace(self, scene_radius=float(radius_m))


def stage_defaults(path: Path = STAGE_CONFIG_PATH) -> dict[str, Any]:
    """The stage's values as the YAML mapping (the one place they are written down)."""
    data = yaml.safe_load(Path(path).read_text()) or {}
    if not isinstance(data, dict):
        raise BenchInputError(path, "expected a mapping of uncertainty-stage parameters")
    return data


def load_stage_config(overrides: Mapping[str, Any] | UncertaintyStageConfig | None = None,
                      path: Path = STAGE_CONFIG_PATH) -> UncertaintyStageConfig:
    """The stage's config: the YAML values <- ``overrides`` (a key the stage does not have is an error).

    A ready :class:`UncertaintyStageConfig` is returned as is.

    Raises:
        BenchInputError (a ValueError): unknown key, wrong type or out-of-range value (names the key).
    """
    if isinstance(overrides, UncertaintyStageConfig):
        return overrides
    return load_config(UncertaintyStageConfig, {**stage_defaults(path), **dict(overrides or {})},
                       f"{path.name} (+ overrides {sorted(overrides or {})})")


@dataclass(frozen=True)
class MonoInstanceConfig(MonoSDFConfig):
    """MonoSDF's keys plus MonoInstance's; documented in ``configs/methods/monoinstance.yaml``."""

    # the three modules of Table 4
    uncertainty: bool
    guided_sampling: bool
    mask_constraint: bool
    # schedule and the uncertainty-weighted losses / sampling
    stage1_fraction: Annotated[float, Range(lo=0, hi=1, lo_open=True, hi_open=True)]
    certainty_cutoff: Annotated[float, Fraction]
    sampling_prob_offset: Annotated[float, NonNegative]
    # instance mask constraint
    mask_weight: Annotated[float, NonNegative]
    mask_n_source: Annotated[int, AtLeastOne]
    mask_min_angle_deg: Annotated[float, Degrees]
    mask_max_angle_deg: Annotated[float, Degrees]
    mask_max_ray_dist: Annotated[float, Positive]
    mask_min_views: Annotated[int, AtLeastOne]
    mask_min_area_frac: Annotated[float, Fraction]
    mask_hit_threshold: Annotated[float, Range(lo=0, hi=1, hi_open=True)]
    mask_count_rule: Literal["code", "ours"]
    mask_source_choice: Literal["random", "nearest"]
    mask_erode_px: Annotated[int, NonNegative]
    mask_renormalise: bool
    mask_normalisation: Literal["code", "ours"]
    # the release's final phase
    final_phase_fraction: Annotated[float, Fraction]
    final_phase_depth_weight: Annotated[float, NonNegative]
    final_phase_normal_weight: Annotated[float, NonNegative]
    final_phase_lr: Annotated[float, Positive] | None
    # overrides of the uncertainty stage's YAML
    uncertainty_stage: dict[str, Any]
    # harness: stage 1 trained once per scene / seed / MonoSDF config and reused (methods.stage_cache)
    share_stage1: bool

    def check(self) -> str | None:
        problem = super().check()
        if problem:
            return problem
        if self.mask_min_angle_deg >= self.mask_max_angle_deg:
            return f"mask_min_angle_deg ({self.mask_min_angle_deg}) must be < mask_max_angle_deg ({self.mask_max_angle_deg})"
        try:
            load_stage_config(self.uncertainty_stage)
        except BenchInputError as bad:
            return f"uncertainty_stage: {bad.problem}"
        return None

    @property
    def modules_on(self) -> bool:
        """Any of the three modules on (else the method is exactly MonoSDF: no stage in between)."""
        return self.uncertainty or self.guided_sampling or self.mask_constraint

    @property
    def stage(self) -> UncertaintyStageConfig:
        """The resolved uncertainty-stage config (YAML values <- ``uncertainty_stage``)."""
        return load_stage_config(self.uncertainty_stage)
