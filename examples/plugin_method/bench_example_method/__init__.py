"""A method plugin for the harness, installed as its own package (``pip install examples/plugin_method``).

``metric_prior_tsdf``: TSDF fusion of the monocular depth prior taken as metric depth (no alignment, no
GT): what a metric depth estimator (e.g. ``sim-metric3d-v2`` scenes) gives without any optimisation. The
harness finds it through the entry point group ``monoinstance_bench.methods`` (pyproject.toml); the
class names its config file with ``config_path`` and its typed config with ``config_type`` (a frozen
dataclass: names and types; the values stay in the YAML; ``bench.data.config``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

import numpy as np

from bench.data.config import Range, load_config
from bench.data.errors import BenchInputError
from methods.base import Artifacts, Snapshot
from metrics.tsdf import block_resolution_for, tsdf_refuse


@dataclass(frozen=True)
class MetricPriorConfig:
    """Keys of ``metric_prior_tsdf.yaml`` (lengths in metres)."""

    depth_scale: Annotated[float, Range(lo=0, lo_open=True)]
    voxel_size: Annotated[float, Range(lo=0, lo_open=True)]
    depth_trunc: Annotated[float, Range(lo=0, lo_open=True)]


class MetricPriorTSDF:
    name = "metric_prior_tsdf"
    config_path = Path(__file__).with_name("metric_prior_tsdf.yaml")
    config_type = MetricPriorConfig

    def fit(self, scene: Any, config: Any, seed: int, progress: Any = None) -> Artifacts:
        cfg = load_config(MetricPriorConfig, config, f"{self.name} config")
        if scene.mono_depth is None:
            raise BenchInputError(scene.root or scene.name, "metric_prior_tsdf needs a monocular depth prior")
        views = scene.view_indices("train")
        depth = np.asarray(scene.mono_depth[views], dtype=np.float32) * cfg.depth_scale
        voxel = cfg.voxel_size
        t = time.perf_counter()
        mesh = tsdf_refuse(None, scene.intrinsics[views], scene.cam_to_world[views], scene.height, scene.width, voxel_size=voxel,
                           sdf_trunc=3 * voxel, depth_trunc=cfg.depth_trunc, depth_maps=depth,
                           block_resolution=block_resolution_for(voxel, 0.16))
        seconds = time.perf_counter() - t
        return Artifacts(snapshots=[Snapshot(1.0, len(views), seconds, mesh=mesh)], timings={"fuse": seconds}, iterations=len(views))
