"""The typed config of the ``monosdf`` method (and of every method built on it).

Names and types only: the values, with the MonoSDF value beside each CPU-driven change, are the YAML
preset ``configs/methods/monosdf.yaml`` (defaults <- scale preset <- overrides, resolved by
:func:`methods.registry.method_config`). :func:`bench.data.config.load_config` fills this class and
rejects unknown keys, missing keys, wrong types and values outside the ranges below.

Units: lengths are in the normalised scene units of the MonoSDF convention (the scene scaled into the
unit sphere by ``Scene.scale_mat``); fractions are of the training schedule (``iterations``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, Literal

from bench.data.config import AtLeastOne, Fraction, NonNegative, Positive, Range


@dataclass(frozen=True)
class MonoSDFConfig:
    """MonoSDF (grid variant) on a CPU; every key is documented in ``configs/methods/monosdf.yaml``."""

    # schedule and batch
    iterations: Annotated[int, AtLeastOne]
    fractions: tuple[Annotated[float, Range(lo=0, hi=1, lo_open=True)], ...]
    rays_per_batch: Annotated[int, AtLeastOne]
    images_per_batch: Annotated[int, AtLeastOne]
    # sampler
    n_coarse: Annotated[int, AtLeastOne]
    n_fine: Annotated[int, NonNegative]
    sampler: Literal["hierarchical", "error_bounded"]
    eb_n_eval: Annotated[int, Range(lo=2)]
    eb_n_final: Annotated[int, AtLeastOne]
    eb_n_extra: Annotated[int, NonNegative]
    eb_eps: Annotated[float, Positive]
    eb_beta_iters: Annotated[int, NonNegative]
    eb_max_rounds: Annotated[int, AtLeastOne]
    near: Annotated[float, Positive]
    bounding_sphere: Annotated[float, Positive]
    # field and its initialisation
    inside_out: bool | Literal["auto"]
    init_radius: Annotated[float, Positive] | Literal["auto"]
    use_grid: bool
    grid_levels: Annotated[int, AtLeastOne]
    grid_features: Annotated[int, AtLeastOne]
    grid_log2_table: Annotated[int, Range(lo=4, hi=24)]
    grid_base_res: Annotated[int, Range(lo=2)]
    grid_max_res: Annotated[int, Range(lo=2)]
    grid_levels_initial: Annotated[int, AtLeastOne] | None
    grid_level_every: Annotated[float, NonNegative]
    mlp_hidden: Annotated[int, AtLeastOne]
    mlp_layers: Annotated[int, AtLeastOne]
    mlp_skip: tuple[Annotated[int, AtLeastOne], ...]
    weight_norm: bool
    geo_features: Annotated[int, AtLeastOne]
    color_hidden: Annotated[int, AtLeastOne]
    color_layers: Annotated[int, AtLeastOne]
    appearance_dim: Annotated[int, NonNegative]
    color_view_dependent: bool
    pe_frequencies: Annotated[int, NonNegative]
    # optimiser
    lr: Annotated[float, Positive]
    grid_lr_factor: Annotated[float, Positive]
    beta_lr_factor: Annotated[float, NonNegative]
    lr_decay: Annotated[float, Positive]
    lr_warmup: Annotated[float, Fraction]
    # density
    beta_init: Annotated[float, Positive]
    beta_min: Annotated[float, NonNegative]
    beta_floor: Annotated[float, NonNegative]
    beta_floor_until: Annotated[float, Fraction]
    # losses
    color_weight: Annotated[float, NonNegative]
    eikonal_weight: Annotated[float, NonNegative]
    depth_weight: Annotated[float, NonNegative]
    depth_warmup: Annotated[float, Fraction]
    prior_loss_form: Literal["monosdf", "code"]
    depth_negative_scale: Literal["keep", "drop"]
    depth_fit: Literal["ssi", "metric"]
    normal_weight: Annotated[float, NonNegative]
    smooth_weight: Annotated[float, NonNegative]
    smooth_jitter: Annotated[float, NonNegative]
    eikonal_ray_sample: Literal["random", "max_weight", "all"]
    prune_weight: Annotated[float, NonNegative]
    # diagnostics, meshing, runtime
    diag_views: Annotated[int, NonNegative]
    diag_stride: Annotated[int, AtLeastOne]
    mesh_resolution: Annotated[int, Range(lo=8)]
    mesh_extent: Annotated[float, Positive] | None
    fast_grid: bool
    flush_denormals: bool
    coarse_gradient_pass: bool
    threads: Annotated[int, NonNegative]

    def samples_per_ray(self) -> int:
        """Samples per ray the renderer evaluates with gradients (before any pruning)."""
        if self.sampler == "error_bounded":
            return self.eb_n_final + min(self.eb_n_extra, self.eb_n_eval) + 2  # + near and far
        return self.n_coarse + self.n_fine

    def check(self) -> str | None:
        """Constraints between keys (``bench.data.config.load_config`` raises the returned problem)."""
        if self.grid_max_res < self.grid_base_res:
            return f"grid_max_res ({self.grid_max_res}) must be >= grid_base_res ({self.grid_base_res})"
        if self.grid_levels_initial is not None and self.grid_levels_initial > self.grid_levels:
            return f"grid_levels_initial ({self.grid_levels_initial}) must be <= grid_levels ({self.grid_levels})"
        pe_width = 3 * (1 + 2 * self.pe_frequencies)
        for layer in self.mlp_skip:
            if layer > self.mlp_layers:
                return f"mlp_skip: layer {layer} is past the SDF MLP's last linear layer ({self.mlp_layers}; mlp_layers = {self.mlp_layers})"
            if self.mlp_hidden <= pe_width:
                return f"mlp_skip needs mlp_hidden ({self.mlp_hidden}) > the encoding's width {pe_width} (pe_frequencies = {self.pe_frequencies})"
        if list(self.fractions) != sorted(self.fractions) or not self.fractions:
            return f"fractions must be a non-empty increasing list in (0, 1], got {list(self.fractions)}"
        return None
