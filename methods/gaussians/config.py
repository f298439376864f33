"""The typed config of the Gaussian-splatting family (``gs3d``, ``fsgs``, ``monoinstance_gs``).

Names and types only: the values are ``configs/methods/gs3d.yaml`` (the family's one preset; ``fsgs`` and
``monoinstance_gs`` inherit it with ``base: gs3d`` and change only the three variant switches).
Units: ``near`` in metres; learning rates as in 3DGS (``lr_means`` x the scene extent); fractions are of
the optimisation steps (``iterations``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, Any, Literal

from bench.data.config import AtLeastOne, Fraction, NonNegative, Positive, Range


@dataclass(frozen=True)
class GaussianConfig:
    """Every key is documented in ``configs/methods/gs3d.yaml``."""

    # variant switches
    depth_loss: Literal["none", "pearson"]
    uncertainty: bool
    mask_constraint: bool
    # schedule
    iterations: Annotated[int, AtLeastOne]
    fractions: tuple[Annotated[float, Range(lo=0, hi=1, lo_open=True)], ...]
    max_gaussians: Annotated[int, AtLeastOne]
    num_threads: Annotated[int, NonNegative]
    # initialisation from the training views
    init_depths: Annotated[int, Range(lo=2)]
    init_max_points: Annotated[int, NonNegative]
    init_random: Annotated[int, NonNegative]
    init_cost: Literal["zero_mean", "sad"]
    init_all_views: bool
    init_cost_ratio: Annotated[float, Positive]
    init_opacity: Annotated[float, Range(lo=0, hi=1, lo_open=True, hi_open=True)]
    init_max_px: Annotated[float, Positive]
    near: Annotated[float, Positive]
    raster_kernel: Literal["cpp", "torch"]
    # losses
    lambda_dssim: Annotated[float, Fraction]
    depth_weight: Annotated[float, NonNegative]
    stage1_fraction: Annotated[float, Range(lo=0, hi=1, lo_open=True, hi_open=True)]
    u_cut: Annotated[float, Fraction]
    mask_weight: Annotated[float, NonNegative]
    mask_u_threshold: Annotated[float, Fraction]
    mask_max_pixels: Annotated[int, AtLeastOne]
    uncertainty_config: dict[str, Any]
    # Adam learning rates
    lr_means: Annotated[float, Positive]
    lr_means_final: Annotated[float, Positive]
    lr_scales: Annotated[float, Positive]
    lr_quats: Annotated[float, Positive]
    lr_opacities: Annotated[float, Positive]
    lr_sh0: Annotated[float, Positive]
    lr_shN: Annotated[float, Positive]
    sh_degree: Literal[0, 1]
    sh_increase_every: Annotated[int, AtLeastOne]
    # densification
    densify_grad_threshold: Annotated[float, Positive]
    percent_dense: Annotated[float, Positive]
    refine_start: Annotated[int, NonNegative]
    refine_every: Annotated[int, AtLeastOne]
    refine_stop_fraction: Annotated[float, Fraction]
    opacity_reset_every: Annotated[int, AtLeastOne]
    prune_opacity: Annotated[float, Fraction]

    def check(self) -> str | None:
        """Constraints between keys (raised by ``bench.data.config.load_config``)."""
        from bench.data.errors import BenchInputError
        from methods.monoinstance.config import load_stage_config

        if self.mask_constraint and not self.uncertainty:
            return "mask_constraint needs uncertainty: true (it acts on high-uncertainty pixels)"
        if list(self.fractions) != sorted(self.fractions) or not self.fractions:
            return f"fractions must be a non-empty increasing list in (0, 1], got {list(self.fractions)}"
        try:
            load_stage_config(self.uncertainty_config)
        except BenchInputError as bad:
            return f"uncertainty_config: {bad.problem}"
        return None
