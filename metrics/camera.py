"""Pinhole camera operations shared by every layer (data, methods, metrics, figures, scripts).

Conventions (the harness's everywhere): OpenCV camera axes (x right, y down, z forward), pixel
centres at integer coordinates (u = column, v = row), intrinsics ``K`` (3, 3) in pixels, extrinsics
``cam_to_world`` (4, 4) mapping camera to world coordinates, depths are z-depths (distance along the
optical axis, metres in scene data; 0 = invalid), everything float64 in NumPy.

The lowest layer that uses them is ``metrics`` (TSDF fusion, culling), so they live here: ``bench.data``
and ``methods`` import them from here; ``metrics`` imports neither of those (tests/test_architecture.py).
The batched many-camera projection of the culling stage (``metrics.culling._project``, chunked over
points for N cameras at once) is its fast path and keeps its own slow twin there.
"""

from __future__ import annotations

import numpy as np

WORLD_UP = np.array([0.0, 0.0, 1.0])


def pixels_to_rays(K: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Camera-frame ray directions with z = 1 through pixel coordinates (u, v) (may be fractional).

    Args:
        K: (3, 3) intrinsics; u, v: (...) column / row coordinates.

    Returns:
        (..., 3) float64 ``inv(K) @ [u, v, 1]`` divided by its z (exactly 1 for a K whose last row is
        [0, 0, 1]), so the point at z-depth d along the pixel is ``d * ray``.
    """
    u = np.asarray(u, dtype=np.float64)
    pix = np.stack([u, np.asarray(v, dtype=np.float64), np.ones_like(u)], axis=-1)
    dirs = pix @ np.linalg.inv(K).T
    return dirs / dirs[..., 2:3]


def pixel_rays(K: np.ndarray, height: int, width: int) -> np.ndarray:
    """(H, W, 3) float64 z = 1 ray directions of every pixel (row-major: ``[v, u]``)."""
    u, v = np.meshgrid(np.arange(width, dtype=np.float64), np.arange(height, dtype=np.float64))
    return pixels_to_rays(K, u, v)


def to_world(points_cam: np.ndarray, cam_to_world: np.ndarray) -> np.ndarray:
    """(..., 3) camera-frame points -> (..., 3) world points."""
    return points_cam @ cam_to_world[:3, :3].T + cam_to_world[:3, 3]


def backproject(depth: np.ndarray, K: np.ndarray, cam_to_world: np.ndarray) -> np.ndarray:
    """A z-depth map -> (H, W, 3) float64 world points (invalid pixels, depth 0, give the camera centre).

    Args:
        depth: (H, W) z-depth; K: (3, 3); cam_to_world: (4, 4).
    """
    return to_world(pixel_rays(K, depth.shape[0], depth.shape[1]) * depth[..., None], cam_to_world)


def backproject_pixels(depth: np.ndarray, rows: np.ndarray, cols: np.ndarray, K: np.ndarray,
                       cam_to_world: np.ndarray) -> np.ndarray:
    """(P, 3) float64 world points of the pixels (rows, cols) of one view at z-depth ``depth[rows, cols]``."""
    z = depth[rows, cols].astype(np.float64)
    return to_world(pixels_to_rays(K, cols, rows) * z[:, None], cam_to_world)


def project(points: np.ndarray, K: np.ndarray, cam_to_world: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World points (P, 3) -> pixel coordinates u, v (P,) and z-depth z (P,) in one camera.

    Points behind the camera (z <= 0) get u = v = NaN; z is returned as is so callers can test it.
    """
    R, t = cam_to_world[:3, :3], cam_to_world[:3, 3]
    cam = (np.asarray(points, dtype=np.float64) - t) @ R  # R^T (x - t), row-wise
    z = cam[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        pix = cam @ K.T
        u = np.where(z > 0, pix[:, 0] / z, np.nan)
        v = np.where(z > 0, pix[:, 1] / z, np.nan)
    return u, v, z


def look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray = WORLD_UP) -> np.ndarray:
    """(4, 4) float64 camera-to-world pose at ``eye`` looking at ``target`` (3-vectors, world metres;
    OpenCV axes: columns right, down, forward; ``up`` the world's up, default +z)."""
    eye, target = np.asarray(eye, dtype=np.float64), np.asarray(target, dtype=np.float64)
    f = target - eye
    f = f / np.linalg.norm(f)
    r = np.cross(f, up)
    if np.linalg.norm(r) < 1e-8:  # looking straight up/down: pick any right vector
        r = np.cross(f, np.array([1.0, 0.0, 0.0]))
    r = r / np.linalg.norm(r)
    d = np.cross(f, r)
    pose = np.eye(4)
    pose[:3, 0], pose[:3, 1], pose[:3, 2], pose[:3, 3] = r, d, f, eye
    return pose
