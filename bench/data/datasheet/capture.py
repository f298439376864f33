"""Capture geometry: how many views see each surface point, from how wide a baseline, how far away.

Surface points: ``n`` points sampled uniformly (area-weighted) on the GT mesh with a fixed seed
(``trimesh.sample.sample_surface``), with their face normals. Without a GT mesh: ``n`` pixels drawn
(fixed seed) from the valid GT depth of up to ``DEPTH_SOURCE_VIEWS`` evenly spaced views, back-projected
to world points with their GT normals (then the sample is pixel-weighted, not area-weighted, and biased
towards the surfaces those views see; the card says which source was used).

A view **sees** a point when the point projects inside the image (pixel centres at integers, the image
spans [-0.5, W - 0.5] x [-0.5, H - 0.5]), lies in front of the camera (z > 0), faces it (the normal
points towards the camera centre: the far side of a wall does not count) and is not occluded: the GT
depth at the nearest pixel is valid and ``|z - depth| < OCCLUSION_TOL_REL * z`` (3 % of the depth:
covers the depth change across half a pixel on surfaces up to ~80 degrees from fronto-parallel at the
harness's ~100 px focal lengths).

Statistics:

* *Candidate* points: those inside the image of, in front of and facing at least one view (the far
  side of a wall, the underside of the floor or of a table top are not candidates: no camera could see
  them). ``frac_hidden``: fraction of the candidates seen by no view (occluded in every view they face).
  The others are the *observed* points.
* ``views_per_point``: 10th percentile, median, 90th percentile of the number of views seeing an
  observed point; ``frac_single_view``: fraction of observed points seen by exactly one view (< 2 views:
  nothing to triangulate); ``views_histogram[k]``: number of candidate points seen by exactly k views
  (k = 0..N).
* ``baseline_depth_ratio``: for a point seen by views i and j, ``|c_i - c_j| / ((|p - c_i| + |p - c_j|) / 2)``
  (camera centres c, metres / metres; about the triangulation angle in radians for small angles);
  ``median_of_median`` = median over points seen by >= 2 views of the median over the point's view
  pairs, ``median_of_max`` likewise of the maximum.
* ``median_distance_m``: median over all valid GT pixels of all views of the Euclidean distance from
  the camera centre to the surface it sees (z-depth times the length of the pixel's z = 1 ray), metres.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from bench.data.scene import Scene
from metrics.camera import backproject_pixels, pixel_rays, project

N_POINTS = 20000
SEED = 0
DEPTH_SOURCE_VIEWS = 10
OCCLUSION_TOL_REL = 0.03
PAIR_BLOCK = 4_000_000  # view pairs x points evaluated at once (memory bound of the pair statistics)


def mesh_surface_points(mesh: Any, n: int = N_POINTS, seed: int = SEED) -> tuple[np.ndarray, np.ndarray]:
    """(n, 3) points uniformly on ``mesh`` (area-weighted, fixed seed) and their (n, 3) unit face normals."""
    import trimesh

    points, faces = trimesh.sample.sample_surface(mesh, n, seed=seed)
    return np.asarray(points, dtype=np.float64), np.asarray(mesh.face_normals, dtype=np.float64)[faces]


def depth_surface_points(scene: Scene, n: int = N_POINTS, seed: int = SEED,
                         max_views: int = DEPTH_SOURCE_VIEWS) -> tuple[np.ndarray, np.ndarray]:
    """(<= n, 3) world points back-projected from the GT depth of up to ``max_views`` evenly spaced
    views (pixels drawn with ``default_rng(seed)``) and their (<= n, 3) world GT normals."""
    depth = np.asarray(scene.gt_depth)
    views = np.unique(np.linspace(0, scene.num_views - 1, min(scene.num_views, max_views)).round().astype(int))
    pts, nrm = [], []
    for v in views:
        rows, cols = np.nonzero(depth[v] > 0)
        pts.append(backproject_pixels(depth[v], rows, cols, scene.intrinsics[v], scene.cam_to_world[v]))
        n_cam = np.asarray(scene.gt_normal[v][rows, cols], dtype=np.float64) if scene.gt_normal is not None else np.zeros((rows.size, 3))
        nrm.append(n_cam @ scene.cam_to_world[v][:3, :3].T)
    points, normals = np.concatenate(pts), np.concatenate(nrm)
    pick = np.random.default_rng(seed).permutation(points.shape[0])[:n]
    return points[pick], normals[pick]


def visibility(points: np.ndarray, normals: np.ndarray, K: np.ndarray, cam_to_world: np.ndarray, depth: np.ndarray,
               tol_rel: float = OCCLUSION_TOL_REL) -> tuple[np.ndarray, np.ndarray]:
    """Which views see which points (module docstring).

    Args:
        points: (P, 3) world metres. normals: (P, 3) world unit normals (a zero normal skips the facing test).
        K: (N, 3, 3). cam_to_world: (N, 4, 4) OpenCV. depth: (N, H, W) GT z-depth, metres, 0 = none.

    Returns:
        (seen, facing): (N, P) bool each; ``facing``: inside the image, in front and facing the view
        (occlusion not tested); ``seen``: also not occluded.
    """
    n_views, h, w = depth.shape
    seen = np.zeros((n_views, points.shape[0]), dtype=bool)
    facing = np.zeros_like(seen)
    for v in range(n_views):
        u, r, z = project(points, K[v], cam_to_world[v])
        inside = (z > 0) & (u >= -0.5) & (u <= w - 0.5) & (r >= -0.5) & (r <= h - 0.5)
        ui = np.clip(np.rint(np.nan_to_num(u)), 0, w - 1).astype(np.int64)
        ri = np.clip(np.rint(np.nan_to_num(r)), 0, h - 1).astype(np.int64)
        d = depth[v][ri, ui].astype(np.float64)
        facing[v] = inside & ((normals * (cam_to_world[v][:3, 3] - points)).sum(1) >= 0)
        seen[v] = facing[v] & (d > 0) & (np.abs(z - d) < tol_rel * np.maximum(z, 0.0))
    return seen, facing


def pair_ratios(seen: np.ndarray, points: np.ndarray, centres: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per point, the median and the maximum over its view pairs of the baseline / depth ratio.

    Args:
        seen: (N, P) bool. points: (P, 3). centres: (N, 3) camera centres, metres.

    Returns:
        (median (P,), max (P,)) float64, NaN for points seen by fewer than two views.
    """
    n_views, n_points = seen.shape
    med = np.full(n_points, np.nan)
    mx = np.full(n_points, np.nan)
    idx = np.flatnonzero(seen.sum(0) >= 2)
    if idx.size == 0:
        return med, mx
    i, j = np.triu_indices(n_views, k=1)
    baseline = np.linalg.norm(centres[i] - centres[j], axis=1)[:, None]
    block = max(1, PAIR_BLOCK // max(i.size, 1))
    for start in range(0, idx.size, block):
        sel = idx[start:start + block]
        dist = np.linalg.norm(points[sel][None] - centres[:, None], axis=2)  # (N, p)
        ok = seen[i][:, sel] & seen[j][:, sel]
        ratio = np.sort(np.where(ok, baseline / (0.5 * (dist[i] + dist[j])), np.nan), axis=0)  # NaN sort last
        k = ok.sum(0)[None]
        lo = np.take_along_axis(ratio, (k - 1) // 2, axis=0)[0]
        hi = np.take_along_axis(ratio, k // 2, axis=0)[0]
        med[sel] = 0.5 * (lo + hi)
        mx[sel] = np.take_along_axis(ratio, k - 1, axis=0)[0]
    return med, mx


def median_viewing_distance(scene: Scene) -> float | None:
    """Median Euclidean camera-to-surface distance over all valid GT pixels of all views, metres."""
    depth = np.asarray(scene.gt_depth, dtype=np.float64)
    dists = []
    for v in range(scene.num_views):
        ok = depth[v] > 0
        ray_length = np.linalg.norm(pixel_rays(scene.intrinsics[v], scene.height, scene.width), axis=2)
        dists.append(depth[v][ok] * ray_length[ok])
    flat = np.concatenate(dists)
    return float(np.median(flat)) if flat.size else None


def capture_stats(scene: Scene, gt_mesh: Any | None = None, n_points: int = N_POINTS, seed: int = SEED) -> dict[str, Any]:
    """The capture statistics of ``scene`` (module docstring); surface points from ``gt_mesh`` when given,
    else from the back-projected GT depth."""
    if gt_mesh is not None:
        points, normals = mesh_surface_points(gt_mesh, n_points, seed)
        source = "gt_mesh"
    else:
        points, normals = depth_surface_points(scene, n_points, seed)
        source = "gt_depth_backprojection"
    seen, facing = visibility(points, normals, scene.intrinsics, scene.cam_to_world, np.asarray(scene.gt_depth))
    count = seen.sum(0)
    observed = count > 0
    candidate = facing.any(0)
    stats: dict[str, Any] = {
        "views": scene.num_views,
        "points_source": source,
        "n_points": int(points.shape[0]),
        "n_candidates": int(candidate.sum()),
        "frac_hidden": float(1.0 - observed.sum() / candidate.sum()) if candidate.any() else None,
        "views_histogram": np.bincount(count[candidate], minlength=scene.num_views + 1).astype(int).tolist(),
        "median_distance_m": median_viewing_distance(scene),
    }
    if observed.any():
        c = count[observed]
        stats["views_per_point"] = {"p10": float(np.percentile(c, 10)), "median": float(np.median(c)), "p90": float(np.percentile(c, 90))}
        stats["frac_single_view"] = float((c == 1).mean())
    else:
        stats["views_per_point"] = {"p10": None, "median": None, "p90": None}
        stats["frac_single_view"] = None
    med, mx = pair_ratios(seen, points, scene.cam_to_world[:, :3, 3])
    multi = np.isfinite(med)
    stats["baseline_depth_ratio"] = {
        "median_of_median": float(np.median(med[multi])) if multi.any() else None,
        "median_of_max": float(np.median(mx[multi])) if multi.any() else None,
    }
    return stats
