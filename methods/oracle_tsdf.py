"""Reference rows by TSDF fusion with open3d: the oracle (GROUND-TRUTH depth, an upper bound) and
"priors only" (``depth_source: prior_aligned``: the monocular depth prior aligned per view to the GT depth
by least-squares scale + shift over the pixels where both are valid, ``metrics.depth.align_depth``; it uses
GT for the alignment, so it is labelled GT-aligned. It tells what the priors alone carry: a neural method
that does not beat it adds nothing to its priors).

Not a method of the paper: it sees GT depth, which no real method has. It exists so the path
run -> metrics -> CSV / markdown works end to end, and as a ceiling for every table. Snapshots fuse
the first 25 / 50 / 100 % of the training views (in capture order), so the accuracy-vs-time curve
shows how coverage grows with views. Fusion is the same projective TSDF the ScanNet protocol uses
(``metrics.tsdf.tsdf_refuse``).
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Annotated, Any, Literal

import numpy as np

from bench.data.config import Range, load_config
from bench.data.errors import BenchInputError
from bench.data.scene import Scene
from methods.base import Artifacts, ProgressFn, Snapshot
from methods.registry import register
from metrics.depth import align_depth
from metrics.tsdf import block_resolution_for, tsdf_refuse


@dataclass(frozen=True)
class OracleConfig:
    """Names and types; the values are ``configs/methods/oracle_tsdf.yaml`` (lengths in metres)."""

    depth_source: Literal["gt", "prior_aligned"]
    voxel_size: Annotated[float, Range(lo=0, lo_open=True)]
    trunc_voxels: Annotated[float, Range(lo=0, lo_open=True)]
    depth_trunc: Annotated[float, Range(lo=0, lo_open=True)]
    block_m: Annotated[float, Range(lo=0, lo_open=True)]
    fractions: tuple[Annotated[float, Range(lo=0, hi=1, lo_open=True)], ...]


def fusion_depth(scene: Scene, views: np.ndarray, source: str) -> np.ndarray:
    """(V, H, W) float32 depth maps (m) of ``views`` to fuse: ``gt`` or ``prior_aligned`` (the mono prior
    with its per-view least-squares scale + shift against GT; pixels where either is 0 stay 0)."""
    if scene.gt_depth is None:
        raise BenchInputError(scene.root or scene.name, "oracle_tsdf needs GT depth maps (synthetic scenes have them)")
    gt = scene.gt_depth[views].astype(np.float32)
    if source == "gt":
        return gt
    if source != "prior_aligned":
        raise BenchInputError("depth_source", f"must be 'gt' or 'prior_aligned', got {source!r}")
    if scene.mono_depth is None:
        raise BenchInputError(scene.root or scene.name, "depth_source: prior_aligned needs a monocular depth prior")
    out = np.zeros_like(gt)
    for i, v in enumerate(views):
        prior = scene.mono_depth[v].astype(np.float64)
        valid = (prior > 0) & (gt[i] > 0)
        if valid.sum() < 2:
            continue
        try:
            s, t = align_depth(prior, gt[i], valid, mode="scale_shift")
        except ValueError:  # a constant prior: no alignment, nothing fused from this view
            continue
        out[i] = np.where(prior > 0, np.maximum(s * prior + t, 0.0), 0.0).astype(np.float32)
    return out


@register("oracle_tsdf")
class OracleTSDF:
    """TSDF fusion of GT depth (upper bound) or of the GT-aligned prior. Config: ``depth_source`` (gt |
    prior_aligned), ``voxel_size`` (m), ``trunc_voxels``, ``depth_trunc`` (m), ``block_m`` (fusion block width,
    m: MonoSDF's 16 cm), ``fractions``."""

    name = "oracle_tsdf"
    config_type = OracleConfig

    def fit(self, scene: Scene, config: Mapping[str, Any], seed: int, progress: ProgressFn | None = None) -> Artifacts:
        cfg = load_config(OracleConfig, config, f"{self.name} config")
        if scene.gt_depth is None:
            raise BenchInputError(scene.root or scene.name, "oracle_tsdf needs GT depth maps (synthetic scenes have them)")
        views = scene.view_indices("train")
        depth = fusion_depth(scene, views, cfg.depth_source)
        voxel = cfg.voxel_size
        snapshots: list[Snapshot] = []
        t0 = time.perf_counter()
        fuse_seconds = 0.0
        for frac in cfg.fractions:
            k = max(1, int(round(frac * len(views))))
            sel = views[:k]
            t = time.perf_counter()
            mesh = tsdf_refuse(None, scene.intrinsics[sel], scene.cam_to_world[sel], scene.height, scene.width, voxel_size=voxel,
                               sdf_trunc=cfg.trunc_voxels * voxel, depth_trunc=cfg.depth_trunc, depth_maps=depth[:k],
                               block_resolution=block_resolution_for(voxel, cfg.block_m))
            fuse_seconds = time.perf_counter() - t
            snapshots.append(Snapshot(fraction=float(frac), iterations=int(k), seconds=fuse_seconds, mesh=mesh))
            if progress:
                progress(float(frac), f"fused {k}/{len(views)} views")
        return Artifacts(snapshots=snapshots, timings={"train": fuse_seconds, "total_method": time.perf_counter() - t0}, iterations=len(views))
