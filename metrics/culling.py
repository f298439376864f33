"""Documented mesh-culling steps used by the evaluation protocols (never hidden inside a metric).

Camera convention: ``cam_to_world`` (N, 4, 4) float64 maps OpenCV camera coordinates (x right, y down,
z forward) to world metres; ``K`` (3, 3) or (N, 3, 3) in pixels with pixel centres at integer
coordinates, so the image covers u in [-0.5, W - 0.5], v in [-0.5, H - 0.5]. Depth maps are z-depth in
metres, 0 = no surface.

Steps:

* :func:`points_in_frusta` / :func:`cull_mesh_to_frusta`: MonoSDF ``replica_eval/cull_mesh.py``: a
  face is removed when all three of its vertices lie outside every camera frustum (behind the camera
  or projecting outside the image).
* :func:`points_visible`: frustum test plus an occlusion test against depth maps rendered at the poses
  (a point counts as seen if ``z <= depth(pixel) + tol`` in at least one view); :func:`views_seeing`
  gives the same test per view (how many views see each point).
  :func:`cull_mesh_to_visible` applies it to faces (kept if any vertex is seen).
* :func:`subdivide_mesh`: split long edges first: vertex-based culling is only meaningful when faces
  are small compared to the frusta (marching-cubes meshes are; synthetic GT walls of two triangles
  are not).
* :func:`crop_mesh_to_bbox`: MonoSDF ``eval_recon.py``: in the frame of the GT's oriented bounding box,
  keep faces whose three vertices lie inside the box scaled by 1.05 about its centre.

Depth rendering at the poses is :mod:`metrics.render`; TSDF re-fusion (MonoSDF's ScanNet evaluation)
is :mod:`metrics.tsdf`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from metrics._checks import as_cameras, as_points, check_positive, to_numpy
from metrics.mesh import clean_mesh
from metrics.render import render_depth_maps


def _world_to_cam(points: np.ndarray, c2w: np.ndarray) -> np.ndarray:
    """(P, 3) world -> (N, P, 3) camera coordinates for N cameras: ``R_n^T (x - t_n)``.

    One (P, 3) x (3, 3N) matrix product for all cameras (an ``einsum`` over the broadcast (N, P, 3)
    difference took 2.5 s of a 6.5 s Replica evaluation); :func:`_world_to_cam_reference` is its
    obviously-correct per-camera twin (tests compare them). Returns a (N, P, 3) view."""
    R = c2w[:, :3, :3]  # [N, 3, 3]
    t = c2w[:, :3, 3]  # [N, 3]
    n = R.shape[0]
    rotated = points @ R.transpose(1, 0, 2).reshape(3, 3 * n)  # [P, 3N]: x^T R_n for every n
    offsets = np.einsum("nj,nji->ni", t, R)  # [N, 3]: t_n^T R_n
    return (rotated.reshape(-1, n, 3) - offsets[None]).transpose(1, 0, 2)


def _world_to_cam_reference(points: np.ndarray, c2w: np.ndarray) -> np.ndarray:
    """Slow twin of :func:`_world_to_cam`: one camera at a time, ``(x - t) R``."""
    return np.stack([(points - c[:3, 3]) @ c[:3, :3] for c in c2w])


def _project(points: np.ndarray, K: np.ndarray, c2w: np.ndarray, chunk: int = 8192):
    """Yield (slice, u, v, z) per chunk of points; u, v, z are (N, p) arrays."""
    for s in range(0, points.shape[0], chunk):
        pc = _world_to_cam(points[s : s + chunk], c2w)  # [N, p, 3]
        z = pc[..., 2]
        zs = np.where(z > 1e-9, z, 1.0)
        u = K[:, 0, 0, None] * pc[..., 0] / zs + K[:, 0, 1, None] * pc[..., 1] / zs + K[:, 0, 2, None]
        v = K[:, 1, 1, None] * pc[..., 1] / zs + K[:, 1, 2, None]
        yield slice(s, s + chunk), u, v, z


def points_in_frusta(points: Any, K: Any, cam_to_world: Any, H: int, W: int) -> np.ndarray:
    """Which points lie inside at least one camera frustum (z > 0 and inside the image).

    Args:
        points: (P, 3) world points, metres.
        K: (3, 3) or (N, 3, 3) intrinsics, pixels.
        cam_to_world: (N, 4, 4) or (4, 4) camera-to-world, OpenCV axes.
        H, W: image size, pixels.

    Returns:
        (P,) bool.
    """
    p = as_points(points, "points", allow_empty=True)
    Km, c2w, h, w = as_cameras(K, cam_to_world, H, W)
    out = np.zeros(p.shape[0], dtype=bool)
    for sl, u, v, z in _project(p, Km, c2w):
        inside = (z > 0) & (u >= -0.5) & (u <= w - 0.5) & (v >= -0.5) & (v <= h - 0.5)
        out[sl] = inside.any(0)
    return out


def _seen(points: Any, K: Any, cam_to_world: Any, H: int, W: int, depth_maps: Any, tol: float):
    """Yield (slice, seen) per chunk of points: seen (N, p) bool, view n sees the point (see :func:`points_visible`)."""
    p = as_points(points, "points", allow_empty=True)
    Km, c2w, h, w = as_cameras(K, cam_to_world, H, W)
    d = np.asarray(to_numpy(depth_maps, "depth_maps"), dtype=np.float64)
    if d.shape != (c2w.shape[0], h, w):
        raise ValueError(f"depth_maps must have shape {(c2w.shape[0], h, w)}, got {tuple(d.shape)}")
    tol = check_positive(tol, "tol", allow_zero=True)
    for sl, u, v, z in _project(p, Km, c2w):
        inside = (z > 0) & (u >= -0.5) & (u <= w - 0.5) & (v >= -0.5) & (v <= h - 0.5)
        ui = np.clip(np.rint(u), 0, w - 1).astype(np.int64)
        vi = np.clip(np.rint(v), 0, h - 1).astype(np.int64)
        dd = d[np.arange(d.shape[0])[:, None], vi, ui]  # [N, p]
        yield sl, inside & ((dd <= 0) | (z <= dd + tol))


def points_visible(
    points: Any,
    K: Any,
    cam_to_world: Any,
    H: int,
    W: int,
    depth_maps: Any,
    tol: float = 0.02,
) -> np.ndarray:
    """Which points are seen by at least one camera: in its frustum and not hidden behind its depth.

    A point projecting to pixel (round(v), round(u)) of view i with z-depth z is seen by view i when
    ``depth_i = 0`` (the ray hits nothing: free space) or ``z <= depth_i + tol``.

    Args:
        points: (P, 3) world points, metres.
        K, cam_to_world, H, W: cameras as in :func:`points_in_frusta`.
        depth_maps: (N, H, W) z-depth maps at those cameras, metres, 0 = no surface.
        tol: occlusion tolerance, metres (surfaces within ``tol`` behind the depth still count).

    Returns:
        (P,) bool.
    """
    out = np.zeros(as_points(points, "points", allow_empty=True).shape[0], dtype=bool)
    for sl, seen in _seen(points, K, cam_to_world, H, W, depth_maps, tol):
        out[sl] = seen.any(0)
    return out


def views_seeing(points: Any, K: Any, cam_to_world: Any, H: int, W: int, depth_maps: Any, tol: float = 0.02) -> np.ndarray:
    """Which views see which points (the test of :func:`points_visible`, per view).

    Returns:
        (N, P) bool: view n sees point p.
    """
    cams = np.asarray(to_numpy(cam_to_world, "cam_to_world"))
    out = np.zeros((1 if cams.ndim == 2 else cams.shape[0], as_points(points, "points", allow_empty=True).shape[0]), dtype=bool)
    for sl, seen in _seen(points, K, cam_to_world, H, W, depth_maps, tol):
        out[:, sl] = seen
    return out


def _keep_faces(mesh: Any, face_mask: np.ndarray):
    import trimesh

    v = np.asarray(mesh.vertices, dtype=np.float64)
    f = np.asarray(mesh.faces, dtype=np.int64)[face_mask]
    out = trimesh.Trimesh(vertices=v, faces=f, process=False)
    out.remove_unreferenced_vertices()
    return out


def subdivide_mesh(mesh: Any, max_edge: float) -> Any:
    """Split faces until no edge is longer than ``max_edge`` metres (same surface, more vertices).

    Faces touching NaN vertices and zero-area faces are dropped first (:func:`metrics.mesh.clean_mesh`).
    """
    import trimesh

    v, f = clean_mesh(mesh)
    me = check_positive(max_edge, "max_edge")
    v2, f2 = trimesh.remesh.subdivide_to_size(v, f, max_edge=me, max_iter=20)
    return trimesh.Trimesh(vertices=v2, faces=f2, process=False)


def cull_mesh_to_frusta(mesh: Any, K: Any, cam_to_world: Any, H: int, W: int) -> Any:
    """Remove faces whose three vertices are all outside every camera frustum (MonoSDF Replica).

    Args:
        mesh: ``trimesh.Trimesh`` in world metres.
        K, cam_to_world, H, W: cameras as in :func:`points_in_frusta`.

    Returns:
        New ``trimesh.Trimesh`` (unreferenced vertices removed; may be empty if nothing is in view).
    """
    v, f = clean_mesh(mesh)
    inside = points_in_frusta(np.nan_to_num(v, nan=1e30, posinf=1e30, neginf=1e30), K, cam_to_world, H, W)
    import trimesh

    return _keep_faces(trimesh.Trimesh(v, f, process=False), inside[f].any(1))


def cull_mesh_to_visible(
    mesh: Any,
    K: Any,
    cam_to_world: Any,
    H: int,
    W: int,
    depth_maps: Any | None = None,
    tol: float = 0.02,
) -> Any:
    """Keep faces with at least one vertex seen by a camera (frustum + occlusion, :func:`points_visible`).

    Args:
        mesh: ``trimesh.Trimesh`` in world metres (subdivide large faces first, :func:`subdivide_mesh`).
        K, cam_to_world, H, W: cameras.
        depth_maps: (N, H, W) z-depth used for occlusion; rendered from ``mesh`` itself when None.
        tol: occlusion tolerance, metres.
    """
    import trimesh

    v, f = clean_mesh(mesh)
    m = trimesh.Trimesh(v, f, process=False)
    if depth_maps is None:
        depth_maps = render_depth_maps(m, K, cam_to_world, H, W)
    seen = points_visible(np.nan_to_num(v, nan=1e30, posinf=1e30, neginf=1e30), K, cam_to_world, H, W, depth_maps, tol)
    return _keep_faces(m, seen[f].any(1))


def gt_bounding_box(gt_mesh: Any, scale: float = 1.05) -> tuple[np.ndarray, np.ndarray]:
    """Oriented bounding box of the GT mesh, scaled about its centre (MonoSDF: x1.05).

    Returns:
        to_box (4, 4) float64 world -> box frame (centred, axis-aligned), half_extents (3,) metres
        already multiplied by ``scale``.
    """
    import trimesh

    v, f = clean_mesh(gt_mesh, "gt_mesh")
    used = np.unique(f)
    s = check_positive(scale, "scale")
    to_box, extents = trimesh.bounds.oriented_bounds(v[used])
    return np.asarray(to_box, dtype=np.float64), 0.5 * np.asarray(extents, dtype=np.float64) * s


def crop_mesh_to_bbox(mesh: Any, to_box: Any, half_extents: Any) -> Any:
    """Keep faces whose three vertices lie strictly inside the box ``|to_box @ x| < half_extents``.

    Args:
        mesh: ``trimesh.Trimesh`` in world metres.
        to_box: (4, 4) world -> box frame (from :func:`gt_bounding_box`).
        half_extents: (3,) half sizes of the box in metres.
    """
    v, f = clean_mesh(mesh)
    T = np.asarray(to_numpy(to_box, "to_box"), dtype=np.float64)
    he = np.asarray(to_numpy(half_extents, "half_extents"), dtype=np.float64)
    if T.shape != (4, 4) or he.shape != (3,):
        raise ValueError(f"to_box must be (4, 4) and half_extents (3,), got {T.shape}, {he.shape}")
    with np.errstate(invalid="ignore"):
        vb = v @ T[:3, :3].T + T[:3, 3]
        inside = (np.abs(vb) < he).all(1)
    import trimesh

    return _keep_faces(trimesh.Trimesh(v, f, process=False), inside[f].all(1))


__all__ = [
    "points_in_frusta",
    "points_visible",
    "subdivide_mesh",
    "cull_mesh_to_frusta",
    "cull_mesh_to_visible",
    "gt_bounding_box",
    "crop_mesh_to_bbox",
]
