"""DTU Chamfer distance, following the official evaluation (Python port used by MonoSDF ``dtu_eval``).

Pipeline (official values in mm for the real DTU objects, ~300-400 mm across):

1. sample the predicted mesh on a regular barycentric grid of spacing ``density`` (0.2 mm), plus its
   vertices (:func:`sample_mesh_dtu`);
2. shuffle (seeded) and greedily keep points at least ``density`` apart (:func:`radius_downsample`);
3. ``data_in``: points inside the bounding box widened by ``patch`` (60 mm; official asymmetric
   bounds ``[BB_min - patch, BB_max + 2 patch)`` kept);
4. ``data_in_obs``: points of ``data_in`` inside the GT box and inside the observation mask. The
   official ObsMask is a voxel grid of the volume the scanner observed; here it is built from the
   scene's visibility (:func:`observation_mask`): a point is observed if some evaluation view (e.g. the
   dense ``eval_only`` views) has it in its frustum and it is not hidden more than ``max_dist``
   behind the GT depth rendered at that view;
5. d2s = mean over ``data_in_obs`` of the distance to the GT points, over distances < ``max_dist`` (20 mm);
6. s2d = mean over GT points above the ground plane (``P . [x, 1] > 0``, skipped when no plane) of the
   distance to ``data_in``, over distances < ``max_dist``;
7. CD = (d2s + s2d) / 2.

Scaling to the downsized scene (:meth:`DTUParams.scaled`): lengths scale with the object size,
``L = L_official * object_size / 350 mm`` (350 mm = a typical DTU object), so the 20 mm cut stays ~6 %
of the object and the 60 mm patch ~17 %. The sampling density is also multiplied by the image
downscale factor (our views have ``1/image_downscale`` of DTU's 1600 px width, so a pixel covers that
many more object millimetres), which keeps the point count near the official one *per pixel* and the
cost tractable on a CPU. Results are reported in scene units (metres); multiply by
``350 mm / object_size`` to read them on DTU's mm scale.

If no point survives a selection, ValueError; if every distance exceeds ``max_dist``, that term is
NaN (what the official script's empty mean gives).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from metrics._checks import as_cameras, as_points, check_positive
from metrics.culling import points_visible
from metrics.mesh import EmptyReconstructionError, check_pred_mesh, clean_mesh
from metrics.nn import nearest_neighbor
from metrics.render import render_depth_maps

DTU_REFERENCE_SIZE_MM = 350.0
DTU_DENSITY_MM = 0.2
DTU_MAX_DIST_MM = 20.0
DTU_PATCH_MM = 60.0


@dataclass(frozen=True)
class DTUParams:
    """Lengths of the DTU evaluation in scene units (metres here).

    Attributes:
        density: sampling spacing and downsampling radius (official 0.2 mm).
        max_dist: distance cut for both means (official 20 mm).
        patch: bounding-box margin for ``data_in`` (official 60 mm).
    """

    density: float
    max_dist: float
    patch: float

    @staticmethod
    def official_mm() -> "DTUParams":
        """The official values, in millimetres (for scenes in mm)."""
        return DTUParams(DTU_DENSITY_MM, DTU_MAX_DIST_MM, DTU_PATCH_MM)

    @staticmethod
    def scaled(object_size: float, image_downscale: float = 1.0) -> "DTUParams":
        """Official values scaled to an object ``object_size`` across (scene units, e.g. metres).

        Args:
            object_size: largest extent of the GT object, scene units.
            image_downscale: DTU width (1600 px) / our image width; multiplies the density only.
        """
        s = check_positive(object_size, "object_size") / DTU_REFERENCE_SIZE_MM
        f = check_positive(image_downscale, "image_downscale")
        return DTUParams(DTU_DENSITY_MM * s * f, DTU_MAX_DIST_MM * s, DTU_PATCH_MM * s)


@dataclass(frozen=True)
class DTUResult:
    """d2s (accuracy), s2d (completeness), chamfer = (d2s + s2d) / 2, in scene units; point counts."""

    d2s: float
    s2d: float
    chamfer: float
    n_pred: int
    n_gt: int

    def as_dict(self) -> dict[str, float]:
        return {"d2s": self.d2s, "s2d": self.s2d, "chamfer": self.chamfer, "n_pred": self.n_pred, "n_gt": self.n_gt}


def sample_mesh_dtu(mesh: Any, density: float, max_points: int = 20_000_000) -> np.ndarray:
    """Regular barycentric-grid sampling of every triangle at spacing ~``density``, plus the vertices.

    For a triangle with edges v1, v2 from vertex 0, ``n_i = floor(|v_i| / (density sqrt(|v1||v2| / |v1 x v2|)))``
    and the samples are ``v0 + a v1 + b v2`` for a = (i + 0.5) / n1, b = (j + 0.5) / n2, a + b < 1.

    Args:
        mesh: ``trimesh.Trimesh`` (scene units). density: spacing, same unit.
        max_points: refuse (ValueError) when the estimate exceeds it, instead of exhausting memory.

    Returns:
        (P, 3) float64 points.
    """
    v, f = clean_mesh(mesh)
    d = check_positive(density, "density")
    tri = v[f]
    e1 = tri[:, 1] - tri[:, 0]
    e2 = tri[:, 2] - tri[:, 0]
    l1 = np.linalg.norm(e1, axis=1)
    l2 = np.linalg.norm(e2, axis=1)
    a2 = np.linalg.norm(np.cross(e1, e2), axis=1)
    thr = d * np.sqrt(l1 * l2 / a2)
    n1 = np.floor(l1 / thr).astype(np.int64)
    n2 = np.floor(l2 / thr).astype(np.int64)
    est = int(((n1 + 1) * (n2 + 1)).sum() // 2)
    if est > max_points:
        raise ValueError(f"DTU sampling at density {d:g} would create ~{est} points (> max_points={max_points}); use a coarser density")
    used = np.unique(f)
    out = [v[used]]
    pairs = np.stack([n1, n2], 1)
    keys, inv = np.unique(pairs, axis=0, return_inverse=True)
    inv = inv.ravel()
    for gi, (a, b) in enumerate(keys):
        if a == 0 or b == 0:
            continue  # official: division by ~0 puts every grid point outside the triangle
        ii, jj = np.mgrid[: a + 1, : b + 1]
        ca = (ii.ravel() + 0.5) / a
        cb = (jj.ravel() + 0.5) / b
        keep = ca + cb < 1
        ca, cb = ca[keep], cb[keep]
        sel = np.flatnonzero(inv == gi)
        pts = tri[sel, 0, None, :] + ca[None, :, None] * e1[sel, None, :] + cb[None, :, None] * e2[sel, None, :]
        out.append(pts.reshape(-1, 3))
    return np.concatenate(out, 0)


def radius_downsample(points: Any, radius: float, seed: int | np.random.Generator = 0) -> np.ndarray:
    """Official greedy downsampling: shuffle, then keep a point and drop its neighbours within ``radius``.

    Args:
        points: (P, 3). radius: scene units. seed: shuffle seed (the official script is unseeded).

    Returns:
        (Q, 3) float64 subset; every pair of kept points is at least ``radius`` apart... except that, as
        in the official loop, a point dropped earlier does not protect its own neighbours.
    """
    from scipy.spatial import cKDTree

    p = as_points(points, "points")
    r = check_positive(radius, "radius")
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    p = p[rng.permutation(p.shape[0])]
    tree = cKDTree(p)
    nbrs = tree.query_ball_point(p, r, workers=-1, return_sorted=False)
    keep = np.ones(p.shape[0], dtype=bool)
    for i, idx in enumerate(nbrs):
        if keep[i]:
            keep[idx] = False
            keep[i] = True
    return p[keep]


def observation_mask(
    points: Any, K: Any, cam_to_world: Any, H: int, W: int, gt_depth_maps: Any, tol: float
) -> np.ndarray:
    """(P,) bool: observed by some view (in frustum, not hidden more than ``tol`` behind GT depth).

    Args:
        points: (P, 3) scene units. K (3, 3) / (N, 3, 3) pixels, cam_to_world (N, 4, 4) OpenCV, H, W.
        gt_depth_maps: (N, H, W) GT z-depth at those views, 0 = no surface (free space counts as seen).
        tol: tolerance behind the surface (the official mask is a dilated volume; we use ``max_dist``).
    """
    return points_visible(points, K, cam_to_world, H, W, gt_depth_maps, tol)


def dtu_chamfer(
    pred_mesh: Any,
    gt_points: Any,
    K: Any,
    cam_to_world: Any,
    H: int,
    W: int,
    params: DTUParams,
    gt_depth_maps: Any | None = None,
    gt_mesh: Any | None = None,
    bbox: Any | None = None,
    ground_plane: Any | None = None,
    seed: int = 0,
) -> DTUResult:
    """DTU Chamfer distance (see the module docstring for every step).

    Args:
        pred_mesh: predicted ``trimesh.Trimesh`` in scene units (metres).
        gt_points: (M, 3) GT points (the "STL" cloud), e.g. from :func:`dtu_gt_points`.
        K, cam_to_world, H, W: the views defining the observation mask (e.g. DTU's dense views).
        params: :class:`DTUParams` in scene units.
        gt_depth_maps: (N, H, W) GT z-depth at the views; rendered from ``gt_mesh`` when None.
        gt_mesh: GT mesh, needed only when ``gt_depth_maps`` is None.
        bbox: (2, 3) [min, max] of the evaluation box; the GT points' box when None.
        ground_plane: optional (4,) plane P; GT points with ``P . [x, 1] > 0`` enter s2d.
        seed: shuffle seed of the radius downsampling.
    """
    check_pred_mesh(pred_mesh)
    g = as_points(gt_points, "gt_points")
    Km, c2w, h, w = as_cameras(K, cam_to_world, H, W)
    if not isinstance(params, DTUParams):
        raise TypeError(f"params must be DTUParams, got {type(params).__name__}")
    if gt_depth_maps is None:
        if gt_mesh is None:
            raise ValueError("give gt_depth_maps or gt_mesh (to render them) for the observation mask")
        gt_depth_maps = render_depth_maps(gt_mesh, Km, c2w, h, w)
    bb = np.stack([g.min(0), g.max(0)]) if bbox is None else np.asarray(bbox, dtype=np.float64)
    if bb.shape != (2, 3):
        raise ValueError(f"bbox must have shape (2, 3), got {bb.shape}")
    plane = None
    if ground_plane is not None:
        plane = np.asarray(ground_plane, dtype=np.float64).reshape(-1)
        if plane.shape != (4,):
            raise ValueError(f"ground_plane must have 4 coefficients, got {plane.shape}")

    data = radius_downsample(sample_mesh_dtu(pred_mesh, params.density), params.density, seed)
    inbound = np.all((data >= bb[0] - params.patch) & (data < bb[1] + 2 * params.patch), axis=1)
    data_in = data[inbound]
    if data_in.shape[0] == 0:
        raise EmptyReconstructionError("no predicted point inside the evaluation bounding box")
    in_box = np.all((data_in >= bb[0]) & (data_in <= bb[1]), axis=1)
    obs = in_box & observation_mask(data_in, Km, c2w, h, w, gt_depth_maps, params.max_dist)
    data_obs = data_in[obs]
    if data_obs.shape[0] == 0:
        raise EmptyReconstructionError("no predicted point inside the observation mask")
    d2s, _ = nearest_neighbor(data_obs, g)
    stl = g if plane is None else g[g @ plane[:3] + plane[3] > 0]
    if stl.shape[0] == 0:
        raise ValueError("no GT point above the ground plane")
    s2d, _ = nearest_neighbor(stl, data_in)
    m_d2s = float(d2s[d2s < params.max_dist].mean()) if np.any(d2s < params.max_dist) else float("nan")
    m_s2d = float(s2d[s2d < params.max_dist].mean()) if np.any(s2d < params.max_dist) else float("nan")
    return DTUResult(m_d2s, m_s2d, 0.5 * (m_d2s + m_s2d), int(data_obs.shape[0]), int(stl.shape[0]))


def dtu_gt_points(
    gt_mesh: Any,
    K: Any,
    cam_to_world: Any,
    H: int,
    W: int,
    params: DTUParams,
    visible_tol: float | None = None,
    seed: int = 0,
) -> np.ndarray:
    """A GT "STL" cloud from a synthetic GT mesh: DTU sampling + downsampling, restricted to surfaces
    seen by the views (the real STL clouds only hold what the scanner saw).

    Args:
        gt_mesh: ``trimesh.Trimesh`` (scene units). K, cam_to_world, H, W: the scanning views.
        params: :class:`DTUParams`. visible_tol: occlusion tolerance (default ``params.max_dist / 4``, 5 mm at DTU scale).
        seed: shuffle seed.

    Returns:
        (M, 3) float64.
    """
    pts = radius_downsample(sample_mesh_dtu(gt_mesh, params.density), params.density, seed)
    depth = render_depth_maps(gt_mesh, K, cam_to_world, H, W)
    tol = params.max_dist / 4 if visible_tol is None else check_positive(visible_tol, "visible_tol")
    seen = points_visible(pts, K, cam_to_world, H, W, depth, tol)
    if not seen.any():
        raise ValueError("no GT point is seen by the given views")
    return pts[seen]
