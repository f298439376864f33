"""Depth maps of a mesh rendered at camera poses (open3d ``RaycastingScene``): what the culling steps
test occlusion against, what TSDF re-fusion integrates, and the diagnostics' reference depth.

Camera convention: :mod:`metrics.camera` (OpenCV axes, pixel centres at integers, z-depth in metres).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from metrics._checks import as_cameras
from metrics.camera import pixel_rays
from metrics.mesh import clean_mesh


def render_depth_maps(mesh: Any, K: Any, cam_to_world: Any, H: int, W: int) -> np.ndarray:
    """Ray-cast z-depth maps of a mesh at the given cameras (open3d ``RaycastingScene``).

    Rays go through pixel centres (integer pixel coordinates) with camera-frame direction
    ``inv(K) @ [u, v, 1]`` (z = 1), so the ray parameter at the hit is the z-depth.

    Returns:
        (N, H, W) float32 z-depth in metres, 0 where the ray hits nothing.
    """
    import open3d as o3d

    v, f = clean_mesh(mesh)
    Km, c2w, h, w = as_cameras(K, cam_to_world, H, W)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor(np.nan_to_num(v, nan=0.0).astype(np.float32)), o3d.core.Tensor(f.astype(np.uint32))
    )
    out = np.zeros((c2w.shape[0], h, w), dtype=np.float32)
    for i in range(c2w.shape[0]):
        d_cam = pixel_rays(Km[i], h, w).reshape(-1, 3)  # z = 1
        d_world = d_cam @ c2w[i, :3, :3].T
        o = np.broadcast_to(c2w[i, :3, 3], d_world.shape)
        rays = np.concatenate([o, d_world], 1).astype(np.float32)
        t = scene.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy()
        t = np.where(np.isfinite(t), t, 0.0)
        out[i] = t.reshape(h, w)
    return out
