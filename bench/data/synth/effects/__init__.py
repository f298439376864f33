"""Effect simulation: what goes wrong in real monocular priors, segmentations and captures.

The synthesizer initialises the priors of a rendered :class:`~bench.data.scene.Scene` to exact ground
truth and calls :func:`apply_effects` with the recipe's effect list; each effect is a small registered
function with typed, validated parameters (see ``EFFECTS`` and ``docs/effects.md``).

Modules: ``depth`` (mono_depth_affine, depth_bleeding, lowfreq_warp, depth_noise), ``normals``
(normal_network, normal_from_depth, normal_rotation), ``failures`` (prior_failure_regions),
``segmentation`` (segmentation_inconsistent), ``image`` (sensor_noise, exposure_change), ``profiles``
(prior_profile, PRIOR_PROFILES = CALIBRATED_PROFILES + LEGACY_PROFILES).
"""

from __future__ import annotations

from . import depth, failures, image, normals, segmentation  # noqa: F401  (register the effects)
from .depth import depth_discontinuities, thin_mask
from .normals import normals_from_depth
from .profiles import CALIBRATED_PROFILES, LEGACY_PROFILES, PRIOR_PROFILES
from .registry import EFFECTS, EffectSpec, apply_effects, register

__all__ = [
    "CALIBRATED_PROFILES",
    "EFFECTS",
    "LEGACY_PROFILES",
    "PRIOR_PROFILES",
    "EffectSpec",
    "apply_effects",
    "depth_discontinuities",
    "normals_from_depth",
    "register",
    "thin_mask",
]
