"""One method family, three registered names: ``gs3d``, ``fsgs``, ``monoinstance_gs``.

They are the same class, :class:`GaussianSplatting`, driven by config (:class:`methods.gaussians.config.GaussianConfig`;
values in ``configs/methods/gs3d.yaml``, which ``fsgs.yaml`` and ``monoinstance_gs.yaml`` inherit):

=================  ==============  ===============  ====================
name               ``depth_loss``  ``uncertainty``  ``mask_constraint``
=================  ==============  ===============  ====================
``gs3d``           none            false            false
``fsgs``           pearson         false            false
``monoinstance_gs`` pearson         true             true
=================  ==============  ===============  ====================

The three subclasses below carry no code: the registry gives each class one name.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from bench.data.config import load_config
from bench.data.scene import Scene
from methods.base import Artifacts, ProgressFn
from methods.gaussians.config import GaussianConfig
from methods.registry import register


class GaussianSplatting:
    """3D Gaussian splatting for sparse views on the CPU; the variant is chosen by the config."""

    name = "gaussian_splatting"
    config_type = GaussianConfig

    def fit(self, scene: Scene, config: Mapping[str, Any], seed: int, progress: ProgressFn | None = None) -> Artifacts:
        from methods.gaussians.train import train_gaussians

        return train_gaussians(scene, load_config(GaussianConfig, config, f"{self.name} config"), seed, progress)


@register("gs3d")
class GS3D(GaussianSplatting):
    """Vanilla 3DGS (photometric loss only)."""


@register("fsgs")
class FSGSStyle(GaussianSplatting):
    """FSGS-style: 3DGS + Pearson depth-correlation loss with the monocular depth of the training views."""


@register("monoinstance_gs")
class MonoInstanceGS(GaussianSplatting):
    """MonoInstance on FSGS: uncertainty-weighted Pearson depth loss + instance-mask constraint."""
