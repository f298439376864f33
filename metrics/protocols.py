"""The two indoor mesh-evaluation protocols of MonoSDF (Table 1 of the paper), as explicit pipelines.

Both take meshes as ``trimesh.Trimesh`` in world metres and the evaluation cameras (``K`` (3, 3) or
(N, 3, 3) pixels; ``cam_to_world`` (N, 4, 4) OpenCV axes; image ``H`` x ``W``), and return
:class:`metrics.mesh.MeshMetrics` (metres and fractions).

Replica (``replica_eval``: ``cull_mesh.py`` + ``eval_recon.py``)
    1. both meshes subdivided to ``max_edge`` (vertex-based culling needs small faces);
    2. GT restricted to what the cameras see. MonoSDF uses a pre-culled GT (``cull_GTmesh``) and
       frustum-culls pred; by default (``gt_visibility="visible"``) we cull *both* meshes with the
       frustum test plus an occlusion test against the GT depth rendered at the poses, because a
       synthetic GT also holds surfaces no camera sees (object bottoms, backs against walls); pred
       uses the GT depth too, so a floater in front of a wall is kept (and penalised) while a guess
       behind it is not. ``"frustum"`` gives MonoSDF's frustum-only culling of both;
    3. pred: crop to the GT's oriented bounding box x1.05;
    4. sample 200k points (with face normals) on each mesh, seeded;
    5. acc / comp / prec / recall / F at 5 cm, Chamfer-L1, normal consistency.

ScanNet (``scannet_eval/evaluate.py``)
    1. pred: TSDF re-fusion from depth rendered at the poses (voxel 1 cm, trunc 3 cm, cut 5 m);
    2. GT: the real ScanNet GT is itself a fusion of the sensor views (visible by construction); our
       synthetic GT is complete, so it goes through the same re-fusion (``refuse_gt=True``);
    3. mesh *vertices* (not surface samples) voxel-downsampled at 2 cm;
    4. acc / comp / prec / recall / F at 5 cm, Chamfer-L1; no normal consistency (NaN).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from metrics._checks import as_cameras, check_int, check_positive
from metrics.culling import crop_mesh_to_bbox, cull_mesh_to_frusta, cull_mesh_to_visible, gt_bounding_box, subdivide_mesh
from metrics.mesh import MeshMetrics, check_pred_mesh, clean_mesh, point_metrics, sample_mesh_surface
from metrics.nn import Backend, NearestNeighborIndex
from metrics.render import render_depth_maps
from metrics.tsdf import MONOSDF_BLOCK_M, block_resolution_for, tsdf_refuse, voxel_downsample


def _nonempty(mesh: Any, what: str) -> Any:
    if len(mesh.faces) == 0:
        raise ValueError(f"{what} is empty after culling: no face is seen by the evaluation cameras")
    return mesh


def nothing_visible_metrics(threshold: float, n_gt: int) -> MeshMetrics:
    """The metrics of a prediction of which nothing is left where the cameras look (after culling,
    cropping or re-fusion): no predicted point, so no GT point is within ``threshold`` of one
    (recall 0) and precision is 0 by convention (as ``zero_division=0``), F-score 0. The distances
    (accuracy, completion, Chamfer) and normal consistency are undefined: NaN, left out of the tables'
    means (shown as "not reported"). ``n_pred`` is 0.

    Example: a no-prior SDF that never carves the room keeps its initial sphere, which lies behind
    every wall. MonoSDF's own evaluation would crash on the empty mesh; a benchmark counts it as F = 0.
    """
    nan = float("nan")
    return MeshMetrics(accuracy=nan, completion=nan, chamfer=nan, precision=0.0, recall=0.0, fscore=0.0,
                       normal_consistency=nan, threshold=float(threshold), n_pred=0, n_gt=int(n_gt))


@dataclass(frozen=True)
class ReplicaGTSurface:
    """The seed-independent GT side of the Replica protocol (steps 1-3): the GT depth maps used to cull
    pred (N, H, W, metres; None with ``gt_visibility="frustum"``), the GT's oriented box (``to_box``
    (4, 4), ``half`` (3,) metres) and the culled GT mesh (``mesh``, world metres)."""

    depth_maps: np.ndarray | None
    to_box: np.ndarray
    half: np.ndarray
    mesh: Any


@dataclass(frozen=True)
class ReplicaGT:
    """The GT side of the Replica protocol for one sampling seed: the :class:`ReplicaGTSurface` fields
    plus its surface samples / normals (``points``, ``normals``: (n_samples, 3)) and their
    nearest-neighbour ``index`` (reused by every snapshot evaluated against this GT)."""

    depth_maps: np.ndarray | None
    to_box: np.ndarray
    half: np.ndarray
    points: np.ndarray
    normals: np.ndarray
    index: NearestNeighborIndex | None = None  # nearest-neighbour index of ``points`` (built once per seed)


def cull_replica_gt(
    gt_mesh: Any,
    K: Any,
    cam_to_world: Any,
    H: int,
    W: int,
    bbox_scale: float = 1.05,
    gt_visibility: Literal["visible", "frustum"] = "visible",
    occlusion_tol: float = 0.02,
    max_edge: float = 0.05,
) -> ReplicaGTSurface:
    """Steps 1-3 of the Replica protocol for the GT mesh (subdivide, cull, oriented box): everything
    but the seeded sampling, so one result serves every seed of a scene (arguments as
    :func:`evaluate_mesh_replica`)."""
    Km, c2w, h, w = as_cameras(K, cam_to_world, H, W)
    clean_mesh(gt_mesh, "gt_mesh")
    if gt_visibility not in ("visible", "frustum"):
        raise ValueError(f"gt_visibility must be 'visible' or 'frustum', got {gt_visibility!r}")
    gt = subdivide_mesh(gt_mesh, max_edge)
    depth = None
    if gt_visibility == "visible":
        depth = render_depth_maps(gt, Km, c2w, h, w)
        gt = cull_mesh_to_visible(gt, Km, c2w, h, w, depth_maps=depth, tol=occlusion_tol)
    else:
        gt = cull_mesh_to_frusta(gt, Km, c2w, h, w)
    _nonempty(gt, "gt_mesh")
    to_box, half = gt_bounding_box(gt, bbox_scale)
    return ReplicaGTSurface(depth, to_box, half, gt)


def sample_replica_gt(surface: ReplicaGTSurface, n_samples: int = 200_000, seed: int = 0) -> ReplicaGT:
    """Step 4 for the GT: ``n_samples`` surface samples of the culled GT with seed ``seed + 1``
    (independent of pred's samples, as MonoSDF)."""
    check_int(n_samples, "n_samples")
    gp, gn = sample_mesh_surface(surface.mesh, n_samples, seed=seed + 1)
    return ReplicaGT(surface.depth_maps, surface.to_box, surface.half, gp, gn, NearestNeighborIndex(gp))


def evaluate_mesh_replica(
    pred_mesh: Any,
    gt_mesh: Any,
    K: Any,
    cam_to_world: Any,
    H: int,
    W: int,
    n_samples: int = 200_000,
    threshold: float = 0.05,
    bbox_scale: float = 1.05,
    gt_visibility: Literal["visible", "frustum"] = "visible",
    occlusion_tol: float = 0.02,
    max_edge: float = 0.05,
    seed: int = 0,
    backend: Backend = "open3d",
    prepared_gt: ReplicaGT | None = None,
) -> MeshMetrics:
    """Replica protocol (MonoSDF ``replica_eval``): cull, crop, sample 200k, metrics with N.C.

    Args:
        pred_mesh: predicted ``trimesh.Trimesh``, world metres.
        gt_mesh: GT ``trimesh.Trimesh``, world metres (unused when ``prepared_gt`` is given).
        K: (3, 3) or (N, 3, 3) intrinsics, pixels. cam_to_world: (N, 4, 4), OpenCV axes.
        H, W: image size, pixels.
        n_samples: surface samples per mesh (200,000 in MonoSDF).
        threshold: precision / recall / F threshold, metres (0.05).
        bbox_scale: GT oriented box scale for cropping pred (1.05).
        gt_visibility: ``"visible"`` (frustum + occlusion by the GT depth, default) or ``"frustum"``
            (MonoSDF's test); applied to both meshes.
        occlusion_tol: occlusion tolerance for ``"visible"``, metres.
        max_edge: faces are subdivided to this edge length before vertex-based culling, metres.
        seed: sampling seed of pred (GT uses ``seed + 1``: independent samples, as MonoSDF).
        backend: nearest-neighbour backend.
        prepared_gt: the GT side from :func:`cull_replica_gt` + :func:`sample_replica_gt` with the same
            cameras, parameters and seed (a cache; None computes it here).

    Returns:
        :class:`MeshMetrics` with normal consistency.

    Raises:
        ValueError: empty / degenerate input mesh, or a GT with nothing left after culling. A pred with
        nothing left after culling or cropping is a result, not an error: :func:`nothing_visible_metrics`.
    """
    Km, c2w, h, w = as_cameras(K, cam_to_world, H, W)
    check_pred_mesh(pred_mesh)
    check_positive(threshold, "threshold")
    if prepared_gt is None:
        surface = cull_replica_gt(gt_mesh, Km, c2w, h, w, bbox_scale=bbox_scale, gt_visibility=gt_visibility,
                                  occlusion_tol=occlusion_tol, max_edge=max_edge)
        prepared_gt = sample_replica_gt(surface, n_samples, seed)
    check_int(n_samples, "n_samples")
    pred = subdivide_mesh(pred_mesh, max_edge)
    if prepared_gt.depth_maps is not None:
        pred = cull_mesh_to_visible(pred, Km, c2w, h, w, depth_maps=prepared_gt.depth_maps, tol=occlusion_tol)
    else:
        pred = cull_mesh_to_frusta(pred, Km, c2w, h, w)
    if len(pred.faces):
        pred = crop_mesh_to_bbox(pred, prepared_gt.to_box, prepared_gt.half)
    if len(pred.faces) == 0:  # nothing of pred where the cameras look (or inside the GT box x bbox_scale)
        return nothing_visible_metrics(threshold, prepared_gt.points.shape[0])
    pp, pn = sample_mesh_surface(pred, n_samples, seed=seed)
    return point_metrics(pp, prepared_gt.points, threshold, pn, prepared_gt.normals, backend=backend, gt_index=prepared_gt.index)


def evaluate_mesh_scannet(
    pred_mesh: Any,
    gt_mesh: Any,
    K: Any,
    cam_to_world: Any,
    H: int,
    W: int,
    threshold: float = 0.05,
    downsample_voxel: float = 0.02,
    tsdf_voxel: float = 0.01,
    tsdf_trunc: float = 0.03,
    depth_trunc: float = 5.0,
    tsdf_block: float = MONOSDF_BLOCK_M,
    refuse_gt: bool = True,
    backend: Backend = "open3d",
    gt_index: NearestNeighborIndex | None = None,
) -> MeshMetrics:
    """ScanNet protocol (MonoSDF ``scannet_eval``): TSDF re-fusion, 2 cm voxel downsampling, metrics.

    Args:
        pred_mesh, gt_mesh: ``trimesh.Trimesh`` in world metres.
        K: (3, 3) or (N, 3, 3) pixels. cam_to_world: (N, 4, 4) OpenCV. H, W: pixels. MonoSDF uses
            every 10th pose of the sequence.
        threshold: precision / recall / F threshold, metres (0.05).
        downsample_voxel: voxel of the vertex downsampling, metres (0.02).
        tsdf_voxel, tsdf_trunc, depth_trunc: re-fusion parameters, metres (0.01, 0.03, 5.0).
        tsdf_block: width of the fusion's blocks, metres (MonoSDF: 16 voxels of 1 cm = 0.16); the voxels
            per block side are :func:`metrics.tsdf.block_resolution_for` ``(tsdf_voxel, tsdf_block)``.
        refuse_gt: also re-fuse the GT (restricts a complete synthetic GT to the observed surface).
        backend: nearest-neighbour backend.
        gt_index: the GT side prepared once (:func:`scannet_gt_points` indexed by
            :class:`metrics.nn.NearestNeighborIndex`); ``gt_mesh`` and ``refuse_gt`` are then unused.

    Returns:
        :class:`MeshMetrics`; ``normal_consistency`` is NaN (the protocol has none); ``n_pred`` /
        ``n_gt`` are the downsampled vertex counts.
    """
    Km, c2w, h, w = as_cameras(K, cam_to_world, H, W)
    check_pred_mesh(pred_mesh)
    check_positive(threshold, "threshold")
    if gt_index is None:
        gv = scannet_gt_points(gt_mesh, Km, c2w, h, w, downsample_voxel, tsdf_voxel, tsdf_trunc, depth_trunc, tsdf_block, refuse_gt)
    else:
        gv = gt_index.points
    pred = tsdf_refuse(pred_mesh, Km, c2w, h, w, **_fusion_args(tsdf_voxel, tsdf_trunc, depth_trunc, tsdf_block))
    if len(pred.vertices) == 0:  # no camera sees any of pred
        return nothing_visible_metrics(threshold, gv.shape[0])
    pv = voxel_downsample(np.asarray(pred.vertices, dtype=np.float64), downsample_voxel)
    return point_metrics(pv, gv, threshold, backend=backend, gt_index=gt_index)


def _fusion_args(tsdf_voxel: float, tsdf_trunc: float, depth_trunc: float, tsdf_block: float) -> dict[str, Any]:
    """:func:`metrics.tsdf.tsdf_refuse` keyword arguments of the ScanNet protocol (pred and GT alike)."""
    return dict(voxel_size=tsdf_voxel, sdf_trunc=tsdf_trunc, depth_trunc=depth_trunc,
                block_resolution=block_resolution_for(tsdf_voxel, tsdf_block))


def scannet_gt_points(
    gt_mesh: Any, K: Any, cam_to_world: Any, H: int, W: int, downsample_voxel: float = 0.02, tsdf_voxel: float = 0.01,
    tsdf_trunc: float = 0.03, depth_trunc: float = 5.0, tsdf_block: float = MONOSDF_BLOCK_M, refuse_gt: bool = True,
) -> np.ndarray:
    """The GT side of :func:`evaluate_mesh_scannet` (same arguments): the GT's vertices (re-fused when
    ``refuse_gt``) voxel-downsampled, (N, 3) metres. Prepared once per scene by ``bench.evaluate``."""
    Km, c2w, h, w = as_cameras(K, cam_to_world, H, W)
    v_gt, f_gt = clean_mesh(gt_mesh, "gt_mesh")
    if refuse_gt:
        kw = _fusion_args(tsdf_voxel, tsdf_trunc, depth_trunc, tsdf_block)
        gt = _nonempty(tsdf_refuse(gt_mesh, Km, c2w, h, w, **kw), "gt_mesh (TSDF re-fused)")
        v_gt = np.asarray(gt.vertices, dtype=np.float64)
    else:
        v_gt = v_gt[np.unique(f_gt)]
    return voxel_downsample(v_gt, downsample_voxel)


__all__ = ["evaluate_mesh_replica", "evaluate_mesh_scannet", "nothing_visible_metrics", "render_depth_maps", "scannet_gt_points"]
