"""Named prior profiles: preset effect lists simulating the error CHARACTER of real estimators.

These are simulations, not the networks: each profile is a list of the registered effects with
parameters chosen once from what the estimators' papers and common experience document (relative vs
metric depth, edge sharpness, thin-structure failures, stochasticity). The rationale for every value,
and the fact that each is an assumption, is in ``docs/effects.md``. They were not tuned to produce any
method ordering.

Pixel sizes (edge widths, opening kernels, correlation lengths) are in pixels of the synthesised
images and were chosen for the harness's small images (about 64-160 px wide).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from bench.data.scene import Scene

from ._params import param
from .registry import apply_effects, register

PRIOR_PROFILES: dict[str, list[dict[str, Any]]] = {
    # Omnidata (DPT-hybrid, scale-and-shift-invariant training; the prior MonoSDF uses): relative depth,
    # noticeable low-frequency bending, smooth/blurred at occlusion edges, often loses thin parts,
    # smooth normals.
    "sim-omnidata": [
        {"name": "mono_depth_affine", "scale": [0.5, 2.0], "shift": [0.0, 0.3], "shift_mode": "relative"},
        {"name": "lowfreq_warp", "amplitude": 0.08, "n_terms": 3, "max_freq": 1.0},
        {
            "name": "depth_bleeding",
            "edge_width_px": 3,
            "edge_threshold": 0.1,
            "edge_strength": 1.0,
            "thin_kernel_px": 5,
            "thin_pull": [0.3, 1.0],
            "thin_vanish_prob": 0.3,
        },
        {"name": "depth_noise", "sigma": 0.005, "correlation_px": 2.0},
        {"name": "normal_from_depth", "blend_gt": 0.0, "smooth_px": 1.5, "align_to_gt": True},
    ],
    # Metric3D v2 (metric depth + normals via a canonical camera space, large ViT, sharp): near-metric
    # scale (small per-view scale error, ~no shift), little bending, sharp edges, fewer thin failures.
    "sim-metric3d-v2": [
        {"name": "mono_depth_affine", "scale": [0.9, 1.1], "shift": [-0.02, 0.02], "shift_mode": "relative"},
        {"name": "lowfreq_warp", "amplitude": 0.03, "n_terms": 3, "max_freq": 1.0},
        {
            "name": "depth_bleeding",
            "edge_width_px": 1,
            "edge_threshold": 0.1,
            "edge_strength": 1.0,
            "thin_kernel_px": 3,
            "thin_pull": [0.0, 0.5],
            "thin_vanish_prob": 0.05,
        },
        {"name": "depth_noise", "sigma": 0.003, "correlation_px": 1.0},
        {"name": "normal_from_depth", "blend_gt": 0.0, "smooth_px": 0.75, "align_to_gt": True},
    ],
    # GeoWizard (Stable-Diffusion-based joint depth-normal, affine-invariant depth): good detail and
    # sharp-ish edges, but each image is a stochastic sample: more per-view variation (correlated,
    # blotchy noise, widely varying thin parts) and a moderate warp.
    "sim-geowizard": [
        {"name": "mono_depth_affine", "scale": [0.5, 2.0], "shift": [0.0, 0.3], "shift_mode": "relative"},
        {"name": "lowfreq_warp", "amplitude": 0.06, "n_terms": 4, "max_freq": 1.5},
        {
            "name": "depth_bleeding",
            "edge_width_px": 2,
            "edge_threshold": 0.1,
            "edge_strength": 1.0,
            "thin_kernel_px": 3,
            "thin_pull": [0.0, 0.8],
            "thin_vanish_prob": 0.1,
        },
        {"name": "depth_noise", "sigma": 0.015, "correlation_px": 3.0},
        {"name": "normal_from_depth", "blend_gt": 0.0, "smooth_px": 1.0, "align_to_gt": True},
    ],
}


@dataclass(frozen=True)
class PriorProfileParams:
    profile: str = param(
        "sim-omnidata", "choice", choices=tuple(PRIOR_PROFILES), doc="name of the simulated estimator profile"
    )


def _expand(p: PriorProfileParams) -> tuple[str, list[dict[str, Any]]]:
    return p.profile, PRIOR_PROFILES[p.profile]


@register("prior_profile", PriorProfileParams, needs=("mono_depth",), expands=_expand)
def prior_profile(scene: Scene, p: PriorProfileParams, rng: np.random.Generator) -> dict[str, Any]:
    """A named preset list of depth/normal prior effects simulating one monocular estimator.

    Models: the error character of a family of real monocular estimators (relative vs metric depth,
    blur at edges, thin-structure failures, per-view stochasticity), as a reproducible preset.

    Profiles (simulations of the error character, not the networks; see docs/effects.md):
    ``sim-omnidata``, ``sim-metric3d-v2``, ``sim-geowizard``. ``apply_effects`` expands the profile
    and records the expanded effects with all their parameters under ``"expanded"``; calling this
    function directly does the same and returns ``{"expanded": [...]}``.

    Parameters: profile (one of ``PRIOR_PROFILES``).
    """
    return {"expanded": apply_effects(scene, PRIOR_PROFILES[p.profile], rng, where=f"profile '{p.profile}'")}
