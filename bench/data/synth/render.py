"""Ray casting of a set of :class:`SceneObject` with open3d's RaycastingScene.

Produces, per view, RGB (albedo from each object's material or texture, then Lambertian shading: the
legacy directional light of :func:`bench.data.synth.shading.shade`, or a room's lights with shadows
and ambient occlusion, :class:`bench.data.synth.lighting.RoomLighting`), z-depth, camera-frame normals
and GT instance ids. Rays are built as ``R @ inv(K) @ [u, v, 1]`` (camera-frame z component 1), so the
hit distance open3d returns is the z-depth directly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d

from bench.data.synth.geometry import SceneObject
from bench.data.synth.lighting import RoomLighting
from bench.data.synth.shading import shade, texture_factor
from metrics.camera import pixel_rays


@dataclass
class RenderedViews:
    """Ground-truth renders of N views of H x W pixels.

    Attributes:
        rgb: (N, H, W, 3) float32 in [0, 1].
        depth: (N, H, W) float32 z-depth in metres, 0 where the ray hits nothing.
        normal: (N, H, W, 3) float32 unit normals in the camera frame (OpenCV), facing the camera; 0 on misses.
        instance: (N, H, W) int32 instance ids (object index + 1), 0 on misses.
    """

    rgb: np.ndarray
    depth: np.ndarray
    normal: np.ndarray
    instance: np.ndarray


class SceneRaycaster:
    """Holds an open3d RaycastingScene for a list of objects; renders views on demand.

    ``lighting``: the room's lights (None: the legacy directional shading, no shadows). The scene it
    casts shadow and ambient-occlusion rays against is this one (every object, decor included)."""

    def __init__(self, objects: list[SceneObject], seed: int = 0, lighting: RoomLighting | None = None) -> None:
        self.objects = objects
        self.lighting = lighting
        self.scene = o3d.t.geometry.RaycastingScene()
        self._geom_to_instance: dict[int, int] = {}
        for idx, obj in enumerate(objects):
            tmesh = o3d.t.geometry.TriangleMesh()
            tmesh.vertex.positions = o3d.core.Tensor(np.asarray(obj.mesh.vertices, dtype=np.float32))
            tmesh.triangle.indices = o3d.core.Tensor(np.asarray(obj.mesh.faces, dtype=np.int32))
            gid = self.scene.add_triangles(tmesh)
            self._geom_to_instance[int(gid)] = idx + 1
        phases = np.random.default_rng(seed).uniform(0, 2 * np.pi, len(objects))
        self._phases = phases
        lut = np.zeros(max(self._geom_to_instance) + 2, dtype=np.int32)
        for gid, inst in self._geom_to_instance.items():
            lut[gid] = inst
        self._lut = lut

    def render(self, K: np.ndarray, cam_to_world: np.ndarray, height: int, width: int) -> tuple[np.ndarray, ...]:
        """Render one view.

        Args:
            K: (3, 3) intrinsics (pixels); cam_to_world: (4, 4) OpenCV pose; height, width: pixels.

        Returns:
            rgb (H, W, 3) float32, depth (H, W) float32 (z-depth, 0 = miss),
            normal (H, W, 3) float32 (camera frame), instance (H, W) int32.
        """
        dirs_cam = pixel_rays(K, height, width).reshape(-1, 3)
        R, t = cam_to_world[:3, :3], cam_to_world[:3, 3]
        dirs_world = dirs_cam @ R.T
        rays = np.concatenate([np.broadcast_to(t, dirs_world.shape), dirs_world], axis=1).astype(np.float32)
        out = self.scene.cast_rays(o3d.core.Tensor(rays))
        t_hit = out["t_hit"].numpy().astype(np.float64)
        gids = out["geometry_ids"].numpy().astype(np.int64)
        n_world = out["primitive_normals"].numpy().astype(np.float64)
        hit = np.isfinite(t_hit)
        gids = np.where(hit, gids, len(self._lut) - 1)
        instance = self._lut[np.clip(gids, 0, len(self._lut) - 1)]
        instance = np.where(hit, instance, 0).astype(np.int32)
        depth = np.where(hit, t_hit, 0.0)

        # orient normals towards the camera
        facing = np.sum(n_world * dirs_world, axis=1) > 0
        n_world[facing] *= -1
        n_world[~hit] = 0.0

        rgb = np.zeros((len(rays), 3))
        pts = t + dirs_world * depth[:, None]
        albedo = np.zeros((len(rays), 3))
        for idx, obj in enumerate(self.objects):
            sel = instance == idx + 1
            if not np.any(sel):
                continue
            albedo[sel] = self.albedo(idx, pts[sel])
            if self.lighting is None:
                rgb[sel] = shade(albedo[sel], n_world[sel])
        if self.lighting is not None and np.any(hit):
            rgb[hit] = self.lighting.shade(self.scene, pts[hit], n_world[hit], albedo[hit])
        n_cam = n_world @ R  # world -> camera: R^T n, written as row-vector product
        return (
            rgb.reshape(height, width, 3).astype(np.float32),
            depth.reshape(height, width).astype(np.float32),
            n_cam.reshape(height, width, 3).astype(np.float32),
            instance.reshape(height, width),
        )

    def albedo(self, idx: int, points: np.ndarray) -> np.ndarray:
        """(M, 3) albedo in [0, 1] of object ``idx`` at (M, 3) world points on it: its material, else
        its base colour times its texture (with the object's phase)."""
        obj = self.objects[idx]
        if obj.material is not None:
            return obj.material.albedo(points)
        tex = texture_factor(obj.texture, points, obj.texture_scale, self._phases[idx])
        return np.clip(obj.albedo[None, :] * tex[:, None], 0.0, 1.0)

    def render_all(self, K: np.ndarray, poses: np.ndarray, height: int, width: int) -> RenderedViews:
        """Render N views: K (N, 3, 3), poses (N, 4, 4)."""
        outs = [self.render(K[i], poses[i], height, width) for i in range(len(poses))]
        return RenderedViews(
            rgb=np.stack([o[0] for o in outs]),
            depth=np.stack([o[1] for o in outs]),
            normal=np.stack([o[2] for o in outs]),
            instance=np.stack([o[3] for o in outs]),
        )
