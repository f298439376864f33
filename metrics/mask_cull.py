"""MonoSDF's DTU mesh culling (``evaluate_single_scene.py`` ``cull_scan``), an option of the DTU protocol.

Before the Chamfer step, MonoSDF's DTU evaluation keeps a mesh vertex only if, in **every** view of the
scan, it either projects outside the image or lands inside that view's object mask dilated by a disk of
12 px (at DTU's 1600 x 1200); faces keep when all three vertices do. Nearest-pixel lookup
(``grid_sample(mode="nearest", align_corners=True)`` in the original). Conventions: ``cam_to_world``
(N, 4, 4) OpenCV axes, ``K`` (N, 3, 3) pixels, integer pixel centres.

On downsized views the 12 px radius is scaled by ``W / 1600`` (at least 1 px): the dilation stays the
same fraction of the image, as the rest of the DTU lengths are scaled (``metrics.dtu``).

:func:`cull_mesh_by_masks` is the vectorised path; the tests compare it with a per-vertex loop.
"""

from __future__ import annotations

from typing import Any

import numpy as np

MONOSDF_DILATION_PX = 12
DTU_WIDTH_PX = 1600


def dilation_radius(width: int, official_px: int = MONOSDF_DILATION_PX, official_width: int = DTU_WIDTH_PX) -> int:
    """The dilation radius in pixels at image width ``width`` (official 12 px at 1600 px, >= 1)."""
    return max(1, int(round(official_px * width / official_width)))


def dilate_masks(masks: np.ndarray, radius: int) -> np.ndarray:
    """(N, H, W) bool masks dilated by a disk of ``radius`` px (scikit-image, as MonoSDF)."""
    from skimage.morphology import dilation, disk

    return np.stack([dilation(m, disk(radius)) for m in np.asarray(masks, dtype=bool)]).astype(bool)


def vertices_kept(vertices: np.ndarray, masks: np.ndarray, K: np.ndarray, cam_to_world: np.ndarray) -> np.ndarray:
    """(V,) bool: the vertex is outside the image or inside the (already dilated) mask in every view.

    Args:
        vertices: (V, 3) world points (metres); masks: (N, H, W) bool; K: (N, 3, 3); cam_to_world: (N, 4, 4).
    """
    v = np.asarray(vertices, dtype=np.float64)
    N, H, W = masks.shape
    keep = np.ones(len(v), dtype=bool)
    for i in range(N):
        w2c = np.linalg.inv(cam_to_world[i])
        pc = v @ w2c[:3, :3].T + w2c[:3, 3]
        uvw = pc @ K[i].T
        z = uvw[:, 2] + 1e-6  # MonoSDF divides by z + 1e-6 (points behind the camera project mirrored, as there)
        u, w = uvw[:, 0] / z, uvw[:, 1] / z
        inside = (u > 0) & (u < W - 1) & (w > 0) & (w < H - 1)  # MonoSDF: normalised coords strictly in (-1, 1)
        ui = np.clip(np.round(u).astype(np.int64), 0, W - 1)
        wi = np.clip(np.round(w).astype(np.int64), 0, H - 1)
        keep &= ~inside | masks[i][wi, ui]
    return keep


def cull_mesh_by_masks(mesh: Any, masks: np.ndarray, K: np.ndarray, cam_to_world: np.ndarray, radius: int | None) -> Any:
    """MonoSDF's ``cull_scan``: the mesh restricted to the vertices :func:`vertices_kept` accepts after
    dilating ``masks`` (N, H, W) by ``radius`` px (None: ``masks`` are dilated already, e.g. cached once
    per scene); faces with a dropped vertex are removed.

    Returns:
        A new ``trimesh.Trimesh`` (possibly empty).
    """
    from metrics.culling import _keep_faces

    dilated = np.asarray(masks, dtype=bool) if radius is None else dilate_masks(masks, radius)
    keep = vertices_kept(np.asarray(mesh.vertices), dilated, np.asarray(K, dtype=np.float64), np.asarray(cam_to_world, dtype=np.float64))
    faces = np.asarray(mesh.faces)
    return _keep_faces(mesh, keep[faces].all(axis=1) if len(faces) else np.zeros(0, dtype=bool))
