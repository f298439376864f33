"""Rays of a Scene in the normalised frame (MonoSDF: ``x_norm = inv(scale_mat) @ x_world``).

The normalised frame maps the scene's region of interest into the unit sphere. For each training view
we precompute the camera centre, per-pixel unit ray directions, the factor turning distance along a
unit ray into z-depth (``1 / |K^-1 [u, v, 1]|``), and the near/far bounds from the bounding sphere.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from bench.data.errors import BenchInputError
from bench.data.scene import Scene
from metrics.camera import pixel_rays


@dataclass
class RayBundle:
    """Per-view ray data of the training views, all float32 torch tensors, normalised units.

    Attributes:
        origins: (V, 3) camera centres.
        dirs: (V, H*W, 3) unit ray directions (world axes).
        z_factor: (V, H*W) multiply a distance along ``dirs`` by this to get z-depth.
        far: (V, H*W) distance to the bounding-sphere exit.
        world_to_cam_rot: (V, 3, 3) rotation world -> camera (for camera-frame normals).
        scale: metres per normalised unit.
    """

    origins: torch.Tensor
    dirs: torch.Tensor
    z_factor: torch.Tensor
    far: torch.Tensor
    world_to_cam_rot: torch.Tensor
    scale: float


def normalisation(scene: Scene) -> tuple[np.ndarray, float]:
    """(centre (3,), scale) of the scene's ``scale_mat`` (a similarity: uniform scale + translation)."""
    return np.asarray(scene.scale_mat, dtype=np.float64)[:3, 3].copy(), scene.metres_per_unit


def camera_rays(K: np.ndarray, cam_to_world: np.ndarray, height: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    """(H*W, 3) float64 unit ray directions of every pixel in world axes (row-major), and (H*W,) the norm of each
    pixel's z = 1 camera ray: a distance along the ray divided by it is the z-depth (OpenCV camera axes)."""
    d_cam = pixel_rays(K, height, width).reshape(-1, 3)  # z = 1
    norm = np.linalg.norm(d_cam, axis=1)
    return (d_cam / norm[:, None]) @ cam_to_world[:3, :3].T, norm


def sphere_exit_distance(origin: np.ndarray, dirs: np.ndarray, radius: float) -> np.ndarray:
    """(P,) distance along unit ``dirs`` (P, 3) from ``origin`` (3,), inside a sphere of ``radius`` about 0, to
    where each ray leaves it (the units of the inputs)."""
    b = dirs @ origin
    c = float(origin @ origin - radius**2)
    return -b + np.sqrt(np.maximum(b * b - c, 0.0))


def build_rays(scene: Scene, views: np.ndarray, radius: float) -> RayBundle:
    """Precompute rays of ``views``; raises BenchInputError if a camera is outside the bounding sphere.

    Args:
        scene: the scene. views: (V,) view indices. radius: bounding-sphere radius (normalised units).
    """
    centre, scale = normalisation(scene)
    origins, dirs, zf, far, rots = [], [], [], [], []
    for v in views:
        K, c2w = scene.intrinsics[v], scene.cam_to_world[v]
        d_world, norm = camera_rays(K, c2w, scene.height, scene.width)
        o = (c2w[:3, 3] - centre) / scale
        if np.linalg.norm(o) >= radius:
            raise BenchInputError(scene.root or scene.name, f"camera {int(v)} is outside the bounding sphere "
                                  f"(|c| = {np.linalg.norm(o):.3f} >= R = {radius} in normalised units); "
                                  "increase the method's bounding_sphere or fix the scene's scale_mat")
        t_far = sphere_exit_distance(o, d_world, radius)
        origins.append(o)
        dirs.append(d_world)
        zf.append(1.0 / norm)
        far.append(t_far)
        rots.append(c2w[:3, :3].T)
    f32 = lambda a: torch.from_numpy(np.asarray(a, dtype=np.float32))  # noqa: E731
    return RayBundle(f32(np.stack(origins)), f32(np.stack(dirs)), f32(np.stack(zf)), f32(np.stack(far)), f32(np.stack(rots)), scale)
