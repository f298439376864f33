"""Evaluation of one method snapshot under a table's protocol (the only place that maps protocols to metrics).

Metric keys produced (the table specs' column keys): ``acc``, ``comp``, ``cd`` (metres), ``prec``,
``recall``, ``fscore`` (fractions at the protocol threshold, 5 cm), ``nc`` (Replica only); ``psnr`` (dB),
``ssim`` for image protocols; DTU: ``cd`` (Chamfer (d2s + s2d) / 2), ``acc`` (d2s), ``comp`` (s2d), metres. Protocol parameters live in ``configs/protocols.yaml`` (per scale).
"""

from __future__ import annotations

from collections import OrderedDict
from pathlib import Path
from typing import Any, Callable

import numpy as np
import yaml

from bench.data.errors import BenchInputError
from bench.data.scene import Scene
from methods.base import Snapshot

PROTOCOLS_FILE = Path(__file__).resolve().parent.parent / "configs" / "protocols.yaml"
SUPPORTED_PROTOCOLS = ("scannet", "replica", "dtu", "llff")
MESH_KEYS = {"accuracy": "acc", "completion": "comp", "chamfer": "cd", "precision": "prec", "recall": "recall", "fscore": "fscore", "normal_consistency": "nc"}


def protocol_params(protocol: str, scale: str, path: Path = PROTOCOLS_FILE) -> dict[str, Any]:
    """Parameters of ``protocol`` at ``scale``: ``defaults`` updated by ``scales[scale]``."""
    data = yaml.safe_load(path.read_text()) or {}
    if protocol not in data:
        raise BenchInputError(path, f"no parameters for protocol {protocol!r}")
    entry = data[protocol]
    scales = entry.get("scales") or {}
    if scale not in scales:
        raise BenchInputError(path, f"protocol {protocol!r} has no scale {scale!r} (has {sorted(scales)})")
    return {**(entry.get("defaults") or {}), **(scales[scale] or {})}


def _mesh_metrics(result: Any) -> dict[str, float]:
    d = result.as_dict()
    out = {short: float(d[long]) for long, short in MESH_KEYS.items() if long in d}
    return {k: v for k, v in out.items() if np.isfinite(v)}


_GT_CACHE: "OrderedDict[tuple, Any]" = OrderedDict()  # GT-side work per scene, least recently used last out
_GT_CACHE_SIZE = 16


def _cached_gt(protocol: str, scene: Scene, params: dict[str, Any], extra: tuple, compute: Callable[[], Any]) -> Any:
    """``compute()`` once per (protocol, scene, parameters, ``extra``): the GT side of an evaluation,
    reused by every snapshot of a job and by the later jobs of the same scene in this process.

    The cache holds at most :data:`_GT_CACHE_SIZE` entries and drops the least recently used one. A
    Replica scene takes one entry for its culled surface and one per seed for the samples, so the dense
    table's small scale needs 10 per worker (2 ScanNet + 2 x (1 + 3) Replica): a worker runs the table
    row by row, cycling through every scene, and a smaller cache recomputed the GT of each scene once per
    row (measured ~20 s per worker over the table)."""
    key = (protocol, str(scene.root or scene.name), tuple(sorted(params.items())), extra)
    if key in _GT_CACHE:
        _GT_CACHE.move_to_end(key)
        return _GT_CACHE[key]
    value = compute()
    _GT_CACHE[key] = value
    while len(_GT_CACHE) > _GT_CACHE_SIZE:
        _GT_CACHE.popitem(last=False)
    return value


def _scannet_gt(scene: Scene, views: np.ndarray, params: dict[str, Any]) -> Any:
    """The ScanNet GT side once per scene: the re-fused GT's downsampled vertices and their
    nearest-neighbour index (:class:`metrics.nn.NearestNeighborIndex`)."""
    from metrics.nn import NearestNeighborIndex
    from metrics.protocols import scannet_gt_points

    cams = (scene.intrinsics[views], scene.cam_to_world[views], scene.height, scene.width)
    keys = ("downsample_voxel", "tsdf_voxel", "tsdf_trunc", "depth_trunc", "tsdf_block")
    return _cached_gt("scannet", scene, params, tuple(int(v) for v in views), lambda: NearestNeighborIndex(
        scannet_gt_points(scene.load_gt_mesh(), *cams, **{k: params[k] for k in keys if k in params})))


def _replica_gt(scene: Scene, views: np.ndarray, params: dict[str, Any], seed: int) -> Any:
    """The Replica GT side: the culled GT surface once per scene (seed-independent: ~4 s at one thread),
    its samples once per seed."""
    from metrics.protocols import cull_replica_gt, sample_replica_gt

    cams = tuple(int(v) for v in views)
    cull_params = {k: v for k, v in params.items() if k not in ("threshold", "n_samples")}
    surface = _cached_gt("replica", scene, params, (cams,), lambda: cull_replica_gt(
        scene.load_gt_mesh(), scene.intrinsics[views], scene.cam_to_world[views], scene.height, scene.width, **cull_params))
    return _cached_gt("replica", scene, params, (cams, seed), lambda: sample_replica_gt(surface, int(params.get("n_samples", 200_000)), seed))


def _crop_to_box(mesh: Any, lo: np.ndarray, hi: np.ndarray) -> Any:
    """Faces of ``mesh`` cut exactly at the six planes of the axis-aligned box [lo, hi] (metres)."""
    import trimesh
    from trimesh.intersections import slice_faces_plane  # numpy only (Trimesh.slice_plane imports shapely)

    v, f = np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64)
    for axis in range(3):
        n = np.zeros(3)
        n[axis] = 1.0
        for origin, normal in ((lo, n), (hi, -n)):
            if len(f):
                v, f = slice_faces_plane(v, f, plane_normal=normal, plane_origin=origin)[:2]
    return trimesh.Trimesh(v, f, process=False)


def dtu_setup(scene: Scene, params: dict[str, Any], seed: int) -> dict[str, Any]:
    """The GT side of the DTU protocol for a DTU-like synthetic scene (cached per scene):

    * lengths: :meth:`metrics.dtu.DTUParams.scaled` from the object's largest extent (the scene's
      ``metadata.layout.object_bounds_m``) and the image downscale ``dtu_width_px / W``;
    * evaluation box (DTU's ObsMask box): the object's box widened by ``patch`` on every side;
    * GT "STL" cloud: the GT mesh (object + ground) cut to the ``data_in`` region
      ``[box_min - patch, box_max + 2 patch)``, DTU-sampled, restricted to what the ``eval_only``
      (dense) views see;
    * observation mask: the same views, with the full GT mesh's depth for occlusion;
    * ground plane P: the scene's ``ground_plane`` raised by ``ground_offset_frac x max_dist``, so
      s2d runs over the object's GT points only (DTU's ``stl_above``);
    * ``cull: monosdf``: every view's object mask, dilated by MonoSDF's 12 px scaled to the width
      (``cull_masks``; None for ``cull: none``).
    """
    from metrics.render import render_depth_maps
    from metrics.dtu import DTUParams, dtu_gt_points

    layout = (scene.metadata or {}).get("layout") or {}
    where = Path(scene.root) / "meta.json" if scene.root else scene.name
    if "object_bounds_m" not in layout or "ground_plane" not in layout:
        raise BenchInputError(where, "the DTU protocol needs metadata.layout.object_bounds_m and ground_plane "
                              "(written by `bench scenes make` for object scenes)")
    bounds = np.asarray(layout["object_bounds_m"], dtype=np.float64)
    dtu = DTUParams.scaled(float((bounds[1] - bounds[0]).max()), image_downscale=float(params["dtu_width_px"]) / scene.width)
    views = scene.view_indices("eval_only") if "eval_only" in scene.splits else np.arange(scene.num_views)
    K, c2w = scene.intrinsics[views], scene.cam_to_world[views]
    bbox = np.stack([bounds[0] - dtu.patch, bounds[1] + dtu.patch])
    gt_mesh = scene.load_gt_mesh()
    region = _crop_to_box(gt_mesh, bbox[0] - dtu.patch, bbox[1] + 2 * dtu.patch)
    cull = str(params.get("cull", "none"))
    if cull not in ("none", "monosdf"):
        raise BenchInputError(PROTOCOLS_FILE, f"dtu.cull must be 'none' or 'monosdf', got {cull!r}")
    cull_masks = None
    if cull == "monosdf":
        from bench.data.formats.dtu import object_masks
        from metrics.mask_cull import dilate_masks, dilation_radius

        cull_masks = dilate_masks(object_masks(scene), dilation_radius(scene.width))
    plane = np.asarray(layout["ground_plane"], dtype=np.float64).copy()
    plane[3] -= float(params["ground_offset_frac"]) * dtu.max_dist * np.linalg.norm(plane[:3])
    return {
        "params": dtu, "bbox": bbox, "plane": plane, "K": K, "c2w": c2w,
        "gt_points": dtu_gt_points(region, K, c2w, scene.height, scene.width, dtu, seed=seed),
        "depth": render_depth_maps(gt_mesh, K, c2w, scene.height, scene.width),
        "cull_masks": cull_masks,
    }


def evaluate_snapshot(snapshot: Snapshot, scene: Scene, protocol: str, scale: str, seed: int = 0) -> dict[str, float]:
    """Metrics of one snapshot.

    Args:
        snapshot: method output (mesh for ``scannet`` / ``replica`` / ``dtu``, renders for ``llff``).
        scene: the evaluated scene (GT mesh, cameras).
        protocol: ``scannet`` | ``replica`` | ``dtu`` | ``llff``.
        scale: selects the protocol parameters (``configs/protocols.yaml``).
        seed: seed of the point sampling in the Replica protocol.

    Returns:
        ``{metric key: value}``.
    """
    if protocol in ("scannet", "replica"):
        from metrics.protocols import evaluate_mesh_replica, evaluate_mesh_scannet

        params = protocol_params(protocol, scale)
        views = scene.view_indices("train")
        cams = (scene.intrinsics[views], scene.cam_to_world[views], scene.height, scene.width)
        if protocol == "scannet":
            gt_index = _scannet_gt(scene, views, params)
            return _mesh_metrics(evaluate_mesh_scannet(snapshot.mesh, None, *cams, gt_index=gt_index, **params))
        prepared = _replica_gt(scene, views, params, seed)
        return _mesh_metrics(evaluate_mesh_replica(snapshot.mesh, None, *cams, seed=seed, prepared_gt=prepared, **params))
    if protocol == "dtu":
        from metrics.dtu import dtu_chamfer

        params = protocol_params(protocol, scale)
        d = _cached_gt("dtu", scene, params, (seed,), lambda: dtu_setup(scene, params, seed))
        mesh = snapshot.mesh
        if d["cull_masks"] is not None:  # MonoSDF's cull_scan: every view's dilated object mask (metrics/mask_cull.py)
            from metrics.mask_cull import cull_mesh_by_masks

            mesh = cull_mesh_by_masks(mesh, d["cull_masks"], scene.intrinsics, scene.cam_to_world, radius=None)
        r = dtu_chamfer(mesh, d["gt_points"], d["K"], d["c2w"], scene.height, scene.width, d["params"],
                        gt_depth_maps=d["depth"], bbox=d["bbox"], ground_plane=d["plane"], seed=seed)
        out = {"cd": r.chamfer, "acc": r.d2s, "comp": r.s2d}
        return {k: float(v) for k, v in out.items() if np.isfinite(v)}
    if protocol == "llff":
        from metrics.image import psnr, ssim

        params = protocol_params(protocol, scale)
        test = scene.view_indices("test")
        return {"psnr": float(psnr(snapshot.renders, scene.images[test]).mean),
                "ssim": float(ssim(snapshot.renders, scene.images[test], padding=str(params["ssim_padding"])).mean)}
    raise BenchInputError(f"protocol {protocol!r}", f"not supported by the evaluator yet {SUPPORTED_PROTOCOLS}")
