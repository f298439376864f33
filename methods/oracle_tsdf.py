"""Oracle reference: TSDF fusion of the GROUND-TRUTH depth maps with open3d (an upper bound).

Not a method of the paper: it sees GT depth, which no real method has. It exists so the path
run -> metrics -> CSV / markdown works end to end, and as a ceiling for every table. Snapshots fuse
the first 25 / 50 / 100 % of the training views (in capture order), so the accuracy-vs-time curve
shows how coverage grows with views. Fusion is the same projective TSDF the ScanNet protocol uses
(``metrics.culling.tsdf_refuse``).
"""

from __future__ import annotations

import time
from typing import Any

from bench.errors import BenchInputError
from bench.scene import Scene
from methods.base import Artifacts, ProgressFn, Snapshot
from methods.registry import register
from metrics.culling import MONOSDF_BLOCK_M, block_resolution_for, tsdf_refuse


@register("oracle_tsdf")
class OracleTSDF:
    """TSDF fusion of GT depth (upper bound). Config: ``voxel_size`` (m), ``trunc_voxels``, ``depth_trunc`` (m), ``block_m`` (fusion block width,
    m: MonoSDF's 16 cm), ``fractions``."""

    name = "oracle_tsdf"

    def fit(self, scene: Scene, config: dict[str, Any], seed: int, progress: ProgressFn | None = None) -> Artifacts:
        if scene.gt_depth is None:
            raise BenchInputError(scene.root or scene.name, "oracle_tsdf needs GT depth maps (synthetic scenes have them)")
        views = scene.view_indices("train")
        voxel = float(config["voxel_size"])
        snapshots: list[Snapshot] = []
        t0 = time.perf_counter()
        fuse_seconds = 0.0
        for frac in config["fractions"]:
            k = max(1, int(round(frac * len(views))))
            sel = views[:k]
            t = time.perf_counter()
            mesh = tsdf_refuse(None, scene.intrinsics[sel], scene.cam_to_world[sel], scene.height, scene.width, voxel_size=voxel,
                               sdf_trunc=float(config["trunc_voxels"]) * voxel, depth_trunc=float(config["depth_trunc"]), depth_maps=scene.gt_depth[sel],
                               block_resolution=block_resolution_for(voxel, float(config.get("block_m", MONOSDF_BLOCK_M))))
            fuse_seconds = time.perf_counter() - t
            snapshots.append(Snapshot(fraction=float(frac), iterations=int(k), seconds=fuse_seconds, mesh=mesh))
            if progress:
                progress(float(frac), f"fused {k}/{len(views)} views")
        return Artifacts(snapshots=snapshots, timings={"train": fuse_seconds, "total_method": time.perf_counter() - t0}, iterations=len(views))
