"""Density-based uncertainty of MonoInstance (paper Sec. 3.2; official ``process_confidence.py``).

For each foreground instance g (global id from :mod:`methods.monoinstance.association`):

2. **Fuse**: back-project the aligned depth of g's pixels in every view where it appears (world metres).
3. **Subsample** the fused cloud at random, without replacement, to at most ``n_subsample`` points
   (code 20,000; paper 30,000), with the caller's ``numpy.random.Generator``.
4. **Clean** (only for the box and the density reference cloud; every pixel is still queried):
   open3d DBSCAN (``dbscan_eps``, ``dbscan_min_points``); label groups (DBSCAN noise counted as one
   group, as the code does with ``labels + 1``; ``drop_dbscan_noise: true`` always drops it) holding
   fewer than ``dbscan_min_cluster_frac`` of the points are removed; then open3d statistical outlier
   removal (``sor_nb_neighbors``, ``sor_std_ratio``; the released file has 0.1 with the comment
   "scannet=2.0, replica=0.1").
5. **Radius**: oriented bounding box of the cleaned cloud (``obb_method: pca`` = open3d
   ``get_oriented_bounding_box`` as the code; ``minimal`` = ``get_minimal_oriented_bounding_box``, the
   paper's minimum box), ``vol`` = product of its extents, ``r = vol + radius_offset``, clamped to
   ``radius_clamp`` if ``use_radius_clamp`` (code only, not in the paper). A degenerate cloud (all
   points identical / collinear / coplanar, where qhull fails) has ``vol = 0``.
6. **Density** of each per-frame pixel point = number of cleaned fused points within r (scipy
   ``cKDTree.query_ball_point(..., return_length=True)``), capped at ``density_cap`` (the code's
   pytorch3d ``ball_query`` has K = 2000). Speed option (not in the code): ``density_ref_points: M``
   counts neighbours among a uniform random subset of M cleaned points instead (cap scaled by the
   kept fraction); step 7 divides by the maximum, so this changes c only by sampling noise.
7. **Certainty** ``c = density / (max_density_frac * max density of g over all its frames + 1e-6)``,
   clipped to [0, 1]; ``U = 1 - c``.
8. Background instances and pixels of no instance: U = 0 (code: c = 1). **Failed** instances get
   ``U = failed_instance_u`` (0.5, supplementary): seen in fewer than ``min_views_per_instance``
   views, fewer than ``min_instance_points`` fused points, cleaning left fewer than
   ``min_instance_points``, or every density is 0. Instance pixels whose aligned depth is invalid
   (0 / non-finite: no 3D point) also get ``failed_instance_u``.

**Units.** The code runs in MonoSDF's normalised scene cube, so its ``eps``, radii and ``vol`` are in
normalised units. Here points are in metres and ``scene_radius`` (metres per normalised unit: the
radius of ``Scene.scale_mat``, x_world = scale_mat @ x_normalised) converts: ``eps_m = eps *
scene_radius``; ``vol_norm = vol_m / scene_radius^3``; ``r_m = r_norm * scene_radius``. With
``scene_radius = 1`` inputs are taken as already normalised.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from methods.monoinstance.config import UncertaintyStageConfig, load_stage_config
from metrics.camera import backproject_pixels


@dataclass
class InstanceUncertainty:
    """Per-instance record of :func:`estimate_uncertainty` (lengths in metres unless ``_norm``)."""

    global_id: int
    status: str  # "ok", "background", or "failed: <reason>"
    n_views: int = 0
    n_pixels: int = 0
    n_fused: int = 0
    n_subsampled: int = 0
    n_clean: int = 0
    obb_volume_norm: float = float("nan")
    radius_norm: float = float("nan")
    radius_m: float = float("nan")
    max_density: float = float("nan")
    mean_u: float = float("nan")
    extra: dict[str, Any] = field(default_factory=dict)


def _obb_volume(pcd, method: str) -> float:
    """Volume (input units^3) of the oriented bounding box; 0 for degenerate clouds (qhull failure)."""
    pts = np.asarray(pcd.points)
    if pts.shape[0] < 4 or np.ptp(pts, axis=0).max() == 0:
        return 0.0
    try:
        box = pcd.get_minimal_oriented_bounding_box() if method == "minimal" else pcd.get_oriented_bounding_box()
        vol = float(np.prod(np.asarray(box.extent)))
    except RuntimeError:  # qhull: coplanar / collinear points
        return 0.0
    return vol if np.isfinite(vol) else 0.0


def scene_radius(cfg: UncertaintyStageConfig) -> float:
    """``cfg.scene_radius`` (metres per normalised unit), which the stage fills from the scene."""
    if cfg.scene_radius is None:
        raise ValueError("estimate_uncertainty needs scene_radius (metres per normalised unit); "
                         "run_uncertainty_stage fills it from Scene.scale_mat")
    return cfg.scene_radius


def clean_cloud(points: np.ndarray, cfg: UncertaintyStageConfig) -> np.ndarray:
    """Step 4: DBSCAN small-group removal then statistical outlier removal (metres in, metres out).

    Args:
        points: (P, 3) fused (subsampled) points, metres.
        cfg: resolved config (``dbscan_*``, ``sor_*``, ``scene_radius``).

    Returns:
        (Q, 3) float64 cleaned points, Q <= P (possibly 0).
    """
    import open3d as o3d

    if points.shape[0] == 0:
        return points.reshape(0, 3)
    pcd = o3d.geometry.PointCloud()
    pcd.points = o3d.utility.Vector3dVector(np.ascontiguousarray(points, dtype=np.float64))
    eps = cfg.dbscan_eps * scene_radius(cfg)
    labels = np.asarray(pcd.cluster_dbscan(eps=eps, min_points=cfg.dbscan_min_points)) + 1  # 0 = noise
    count = np.bincount(labels)
    keep_label = count >= cfg.dbscan_min_cluster_frac * labels.size
    if cfg.drop_dbscan_noise:
        keep_label[0] = False
    idx = np.flatnonzero(keep_label[labels])
    if idx.size == 0:
        return points[:0]
    pcd = pcd.select_by_index(idx.tolist())
    if idx.size > cfg.sor_nb_neighbors:
        pcd, _ = pcd.remove_statistical_outlier(nb_neighbors=cfg.sor_nb_neighbors, std_ratio=cfg.sor_std_ratio)
    return np.asarray(pcd.points)


def ball_radius_norm(points_m: np.ndarray, cfg: UncertaintyStageConfig) -> tuple[float, float]:
    """Step 5: (obb volume, ball radius), both in normalised units, of a cleaned cloud in metres."""
    import open3d as o3d

    R = scene_radius(cfg)
    pcd = o3d.geometry.PointCloud()
    pcd.points = o3d.utility.Vector3dVector(np.ascontiguousarray(points_m / R, dtype=np.float64))
    vol = _obb_volume(pcd, cfg.obb_method)
    r = vol + cfg.radius_offset
    if cfg.use_radius_clamp:
        lo, hi = cfg.radius_clamp
        r = min(max(r, float(lo)), float(hi))
    return vol, r


def certainty_from_densities(densities: list[np.ndarray], max_density_frac: float = 0.8) -> list[np.ndarray] | None:
    """Step 7: per-frame certainty ``c = clip(d / (frac * max_all_frames d + 1e-6), 0, 1)``.

    Args:
        densities: per frame, (P_i,) neighbour counts of that frame's pixel points.
        max_density_frac: the code's 0.8.

    Returns:
        per frame (P_i,) float64 c in [0, 1], or None if there is no density at all (no points, or
        every density is 0: the instance is treated as failed by the caller).
    """
    if not densities or sum(d.size for d in densities) == 0:
        return None
    mx = max(float(d.max()) for d in densities if d.size)
    if mx <= 0:
        return None
    return [np.clip(d.astype(np.float64) / (max_density_frac * mx + 1e-6), 0.0, 1.0) for d in densities]


def estimate_uncertainty(
    depth: np.ndarray,
    global_ids: np.ndarray,
    is_background: dict[int, bool],
    K: np.ndarray,
    cam_to_world: np.ndarray,
    config: UncertaintyStageConfig | Mapping[str, Any] | None = None,
    rng: np.random.Generator | int | None = None,
) -> tuple[np.ndarray, dict[int, InstanceUncertainty]]:
    """Per-pixel uncertainty U = 1 - c from the multi-view density of each instance (module docstring).

    Args:
        depth: (N, H, W) aligned metric z-depth (metres; 0 / non-finite = invalid).
        global_ids: (N, H, W) int multi-view consistent instance ids, 0 = none.
        is_background: global id -> True for background (ids absent from it count as foreground).
        K: (N, 3, 3) or (3, 3) intrinsics, pixels. cam_to_world: (N, 4, 4), OpenCV axes, metres.
        config: the stage's config (:class:`methods.monoinstance.config.UncertaintyStageConfig`, or
            overrides of its YAML). ``scene_radius`` (must be set here) converts the code's normalised
            units (see module docstring).
        rng: ``numpy.random.Generator`` (or an int seed) for the subsampling; same seed, same U.

    Returns:
        U (N, H, W) float32 in [0, 1] (0 on background and non-instance pixels), and a dict
        global id -> :class:`InstanceUncertainty` (foreground and background instances).
    """
    from scipy.spatial import cKDTree

    cfg = load_stage_config(config)
    R = scene_radius(cfg)
    rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
    dep = np.asarray(depth)
    gids = np.asarray(global_ids)
    if dep.ndim != 3 or gids.shape != dep.shape:
        raise ValueError(f"depth and global_ids must both be (N, H, W), got {dep.shape} and {gids.shape}")
    n_views = dep.shape[0]
    K = np.broadcast_to(np.asarray(K, dtype=np.float64), (n_views, 3, 3))
    c2w = np.asarray(cam_to_world, dtype=np.float64)
    if c2w.shape != (n_views, 4, 4):
        raise ValueError(f"cam_to_world must be ({n_views}, 4, 4), got {c2w.shape}")
    U = np.zeros(dep.shape, dtype=np.float32)
    valid = np.isfinite(dep) & (dep > 0)
    fail_u = cfg.failed_instance_u
    info: dict[int, InstanceUncertainty] = {}

    for g in (int(x) for x in np.unique(gids)):
        if g == 0:
            continue
        mask_g = gids == g
        if is_background.get(g, False):
            info[g] = InstanceUncertainty(g, "background", n_pixels=int(mask_g.sum()), mean_u=0.0)
            continue
        rec = InstanceUncertainty(g, "ok", n_pixels=int(mask_g.sum()))
        info[g] = rec
        frames = [v for v in range(n_views) if mask_g[v].any()]
        rec.n_views = len(frames)
        U[mask_g & ~valid] = fail_u  # instance pixels with no 3D point
        per_frame: list[tuple[int, np.ndarray, np.ndarray, np.ndarray]] = []
        for v in frames:
            rows, cols = np.nonzero(mask_g[v] & valid[v])
            if rows.size:
                per_frame.append((v, rows, cols, backproject_pixels(dep[v], rows, cols, K[v], c2w[v])))
        fused = np.concatenate([p for *_, p in per_frame]) if per_frame else np.zeros((0, 3))
        rec.n_fused = int(fused.shape[0])

        def fail(reason: str) -> None:
            rec.status = f"failed: {reason}"
            U[mask_g] = fail_u
            rec.mean_u = fail_u

        if rec.n_views < cfg.min_views_per_instance:
            fail(f"seen in {rec.n_views} view(s) < min_views_per_instance={cfg.min_views_per_instance}")
            continue
        if rec.n_fused < cfg.min_instance_points:
            fail(f"{rec.n_fused} fused points < min_instance_points={cfg.min_instance_points}")
            continue
        if not np.all(np.isfinite(fused)):
            fail("non-finite back-projected points (bad camera?)")
            continue
        k = min(cfg.n_subsample, rec.n_fused)
        sub = fused[np.sort(rng.choice(rec.n_fused, size=k, replace=False))]
        rec.n_subsampled = k
        clean = clean_cloud(sub, cfg)
        rec.n_clean = int(clean.shape[0])
        if rec.n_clean < cfg.min_instance_points:
            fail(f"{rec.n_clean} points left after cleaning < min_instance_points={cfg.min_instance_points}")
            continue
        rec.obb_volume_norm, rec.radius_norm = ball_radius_norm(clean, cfg)
        rec.radius_m = rec.radius_norm * R
        ref, cap = clean, float(cfg.density_cap)
        if cfg.density_ref_points is not None and clean.shape[0] > cfg.density_ref_points:
            # speed option: count neighbours in a uniform random subset; counts (and the cap) scale by
            # the kept fraction, which the max-normalisation of step 7 cancels up to sampling noise
            keep = cfg.density_ref_points
            ref = clean[np.sort(rng.choice(clean.shape[0], size=keep, replace=False))]
            cap *= keep / clean.shape[0]
        tree = cKDTree(ref)
        dens = [np.minimum(tree.query_ball_point(p, rec.radius_m, return_length=True), cap) for *_, p in per_frame]
        cert = certainty_from_densities(dens, cfg.max_density_frac)
        if cert is None:
            fail("all densities are 0")
            continue
        rec.max_density = float(max(d.max() for d in dens if d.size))
        for (v, rows, cols, _p), c in zip(per_frame, cert):
            U[v, rows, cols] = (1.0 - c).astype(np.float32)
        rec.mean_u = float(U[mask_g].mean())
    np.clip(U, 0.0, 1.0, out=U)
    return U, info
