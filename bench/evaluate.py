"""Evaluation of one method snapshot under a table's protocol (the only place that maps protocols to metrics).

Metric keys produced (the table specs' column keys): ``acc``, ``comp``, ``cd`` (metres), ``prec``,
``recall``, ``fscore`` (fractions at the protocol threshold, 5 cm), ``nc`` (Replica only); ``psnr`` (dB),
``ssim`` for image protocols; DTU: ``cd`` (Chamfer (d2s + s2d) / 2), ``acc`` (d2s), ``comp`` (s2d), metres. Protocol parameters live in ``configs/protocols.yaml`` (per scale).
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Callable, Literal

import numpy as np
import yaml

from bench.data.config import Range, config_record, load_config
from bench.data.errors import BenchInputError
from bench.data.scene import Scene
from methods.base import Snapshot

PROTOCOLS_FILE = Path(__file__).resolve().parent.parent / "configs" / "protocols.yaml"
MESH_KEYS = {"accuracy": "acc", "completion": "comp", "chamfer": "cd", "precision": "prec", "recall": "recall", "fscore": "fscore", "normal_consistency": "nc"}
Positive = Range(lo=0, lo_open=True)


@dataclass(frozen=True)
class ScanNetParams:
    """MonoSDF's ScanNet evaluation (metres): F-score ``threshold``, the re-fusion of the prediction
    (``tsdf_voxel`` / ``tsdf_trunc`` / ``depth_trunc`` / ``tsdf_block``) and the down-sampling voxel."""

    threshold: Annotated[float, Positive]
    downsample_voxel: Annotated[float, Positive]
    tsdf_voxel: Annotated[float, Positive]
    tsdf_trunc: Annotated[float, Positive]
    depth_trunc: Annotated[float, Positive]
    tsdf_block: Annotated[float, Positive]


@dataclass(frozen=True)
class ReplicaParams:
    """MonoSDF's Replica evaluation: ``n_samples`` surface samples, ``threshold`` (m), GT box scale."""

    n_samples: Annotated[int, Range(lo=1)]
    threshold: Annotated[float, Positive]
    bbox_scale: Annotated[float, Positive]


@dataclass(frozen=True)
class DTUProtocolParams:
    """The DTU evaluation: lengths scaled from DTU's ``dtu_width_px`` images, the ground-plane offset,
    and the optional MonoSDF mask culling (``cull``: none | monosdf; docs/metrics.md)."""

    dtu_width_px: Annotated[int, Range(lo=1)]
    ground_offset_frac: Annotated[float, Range(lo=0)]
    cull: Literal["none", "monosdf"]


@dataclass(frozen=True)
class LLFFParams:
    """The LLFF image evaluation: SSIM border convention (zero = FSGS's zero-padded window; valid)."""

    ssim_padding: Literal["zero", "valid"]


@dataclass(frozen=True)
class Protocol:
    """An evaluation protocol: its typed parameters (values in ``configs/protocols.yaml``, per scale) and
    ``evaluate(snapshot, scene, params, seed) -> {metric key: value}``."""

    name: str
    params_type: type
    evaluate: Callable[[Snapshot, Scene, Any, int], dict[str, float]]


PROTOCOL_REGISTRY: dict[str, Protocol] = {}


def register_protocol(name: str, params_type: type) -> Callable[[Callable], Callable]:
    """Decorator: ``@register_protocol("scannet", ScanNetParams)`` on the evaluation function."""

    def deco(fn: Callable) -> Callable:
        if name in PROTOCOL_REGISTRY:
            raise ValueError(f"protocol {name!r} registered twice")
        PROTOCOL_REGISTRY[name] = Protocol(name, params_type, fn)
        return fn

    return deco


def get_protocol(name: str) -> Protocol:
    if name not in PROTOCOL_REGISTRY:
        raise BenchInputError(f"protocol {name!r}", f"not supported by the evaluator (available: {sorted(PROTOCOL_REGISTRY)})")
    return PROTOCOL_REGISTRY[name]


def protocol_params(protocol: str, scale: str, path: Path = PROTOCOLS_FILE) -> Any:
    """Typed parameters of ``protocol`` at ``scale``: the file's ``defaults`` updated by ``scales[scale]``
    (unknown keys, wrong types and out-of-range values are errors naming the file)."""
    data = yaml.safe_load(path.read_text()) or {}
    if protocol not in data:
        raise BenchInputError(path, f"no parameters for protocol {protocol!r}")
    entry = data[protocol]
    scales = entry.get("scales") or {}
    if scale not in scales:
        raise BenchInputError(path, f"protocol {protocol!r} has no scale {scale!r} (has {sorted(scales)})")
    values = {**(entry.get("defaults") or {}), **(scales[scale] or {})}
    return load_config(get_protocol(protocol).params_type, values, f"{path} ({protocol}, scale {scale!r})")


def _mesh_metrics(result: Any) -> dict[str, float]:
    d = result.as_dict()
    out = {short: float(d[long]) for long, short in MESH_KEYS.items() if long in d}
    return {k: v for k, v in out.items() if np.isfinite(v)}


_GT_CACHE: "OrderedDict[tuple, Any]" = OrderedDict()  # GT-side work per scene, least recently used last out
_GT_CACHE_SIZE = 16


def _cached_gt(protocol: str, scene: Scene, params: Any, extra: tuple, compute: Callable[[], Any]) -> Any:
    """``compute()`` once per (protocol, scene, parameters, ``extra``): the GT side of an evaluation,
    reused by every snapshot of a job and by the later jobs of the same scene in this process.

    The cache holds at most :data:`_GT_CACHE_SIZE` entries and drops the least recently used one. A
    Replica scene takes one entry for its culled surface and one per seed for the samples, so the dense
    table's small scale needs 10 per worker (2 ScanNet + 2 x (1 + 3) Replica): a worker runs the table
    row by row, cycling through every scene, and a smaller cache recomputed the GT of each scene once per
    row (measured ~20 s per worker over the table)."""
    key = (protocol, str(scene.root or scene.name), params, extra)  # params: a frozen (hashable) dataclass
    if key in _GT_CACHE:
        _GT_CACHE.move_to_end(key)
        return _GT_CACHE[key]
    value = compute()
    _GT_CACHE[key] = value
    while len(_GT_CACHE) > _GT_CACHE_SIZE:
        _GT_CACHE.popitem(last=False)
    return value


def _scannet_gt(scene: Scene, views: np.ndarray, params: ScanNetParams) -> Any:
    """The ScanNet GT side once per scene: the re-fused GT's downsampled vertices and their
    nearest-neighbour index (:class:`metrics.nn.NearestNeighborIndex`)."""
    from metrics.nn import NearestNeighborIndex
    from metrics.protocols import scannet_gt_points

    cams = (scene.intrinsics[views], scene.cam_to_world[views], scene.height, scene.width)
    return _cached_gt("scannet", scene, params, tuple(int(v) for v in views), lambda: NearestNeighborIndex(
        scannet_gt_points(scene.load_gt_mesh(), *cams, downsample_voxel=params.downsample_voxel, tsdf_voxel=params.tsdf_voxel,
                          tsdf_trunc=params.tsdf_trunc, depth_trunc=params.depth_trunc, tsdf_block=params.tsdf_block)))


def _replica_gt(scene: Scene, views: np.ndarray, params: ReplicaParams, seed: int) -> Any:
    """The Replica GT side: the culled GT surface once per scene (seed-independent: ~4 s at one thread),
    its samples once per seed."""
    from metrics.protocols import cull_replica_gt, sample_replica_gt

    cams = tuple(int(v) for v in views)
    surface = _cached_gt("replica", scene, params, (cams,), lambda: cull_replica_gt(
        scene.load_gt_mesh(), scene.intrinsics[views], scene.cam_to_world[views], scene.height, scene.width, bbox_scale=params.bbox_scale))
    return _cached_gt("replica", scene, params, (cams, seed), lambda: sample_replica_gt(surface, params.n_samples, seed))


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


def dtu_setup(scene: Scene, params: DTUProtocolParams, seed: int) -> dict[str, Any]:
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
    from metrics.dtu import DTUParams, dtu_gt_points
    from metrics.render import render_depth_maps

    layout = (scene.metadata or {}).get("layout") or {}
    where = Path(scene.root) / "meta.json" if scene.root else scene.name
    if "object_bounds_m" not in layout or "ground_plane" not in layout:
        raise BenchInputError(where, "the DTU protocol needs metadata.layout.object_bounds_m and ground_plane "
                              "(written by `bench scenes make` for object scenes)")
    bounds = np.asarray(layout["object_bounds_m"], dtype=np.float64)
    dtu = DTUParams.scaled(float((bounds[1] - bounds[0]).max()), image_downscale=float(params.dtu_width_px) / scene.width)
    views = scene.view_indices("eval_only") if "eval_only" in scene.splits else np.arange(scene.num_views)
    K, c2w = scene.intrinsics[views], scene.cam_to_world[views]
    bbox = np.stack([bounds[0] - dtu.patch, bounds[1] + dtu.patch])
    gt_mesh = scene.load_gt_mesh()
    region = _crop_to_box(gt_mesh, bbox[0] - dtu.patch, bbox[1] + 2 * dtu.patch)
    cull_masks = None
    if params.cull == "monosdf":
        from bench.data.formats.dtu import object_masks
        from metrics.mask_cull import dilate_masks, dilation_radius

        cull_masks = dilate_masks(object_masks(scene), dilation_radius(scene.width))
    plane = np.asarray(layout["ground_plane"], dtype=np.float64).copy()
    plane[3] -= params.ground_offset_frac * dtu.max_dist * np.linalg.norm(plane[:3])
    return {
        "params": dtu, "bbox": bbox, "plane": plane, "K": K, "c2w": c2w,
        "gt_points": dtu_gt_points(region, K, c2w, scene.height, scene.width, dtu, seed=seed),
        "depth": render_depth_maps(gt_mesh, K, c2w, scene.height, scene.width),
        "cull_masks": cull_masks,
    }


@register_protocol("scannet", ScanNetParams)
def evaluate_scannet(snapshot: Snapshot, scene: Scene, params: ScanNetParams, seed: int) -> dict[str, float]:
    """MonoSDF's ScanNet protocol on the training views: re-fused prediction vs re-fused GT."""
    from metrics.protocols import evaluate_mesh_scannet

    views = scene.view_indices("train")
    cams = (scene.intrinsics[views], scene.cam_to_world[views], scene.height, scene.width)
    gt_index = _scannet_gt(scene, views, params)
    return _mesh_metrics(evaluate_mesh_scannet(snapshot.mesh, None, *cams, gt_index=gt_index, **config_record(params)))


@register_protocol("replica", ReplicaParams)
def evaluate_replica(snapshot: Snapshot, scene: Scene, params: ReplicaParams, seed: int) -> dict[str, float]:
    """MonoSDF's Replica protocol: culled GT surface, ``n_samples`` samples (seeded), normal consistency."""
    from metrics.protocols import evaluate_mesh_replica

    views = scene.view_indices("train")
    cams = (scene.intrinsics[views], scene.cam_to_world[views], scene.height, scene.width)
    prepared = _replica_gt(scene, views, params, seed)
    return _mesh_metrics(evaluate_mesh_replica(snapshot.mesh, None, *cams, seed=seed, prepared_gt=prepared, **config_record(params)))


@register_protocol("dtu", DTUProtocolParams)
def evaluate_dtu(snapshot: Snapshot, scene: Scene, params: DTUProtocolParams, seed: int) -> dict[str, float]:
    """The DTU Chamfer (:func:`dtu_setup`; MonoSDF's mask culling first when ``cull: monosdf``)."""
    from metrics.dtu import dtu_chamfer

    d = _cached_gt("dtu", scene, params, (seed,), lambda: dtu_setup(scene, params, seed))
    mesh = snapshot.mesh
    if d["cull_masks"] is not None:  # MonoSDF's cull_scan: every view's dilated object mask (metrics/mask_cull.py)
        from metrics.mask_cull import cull_mesh_by_masks

        mesh = cull_mesh_by_masks(mesh, d["cull_masks"], scene.intrinsics, scene.cam_to_world, radius=None)
    r = dtu_chamfer(mesh, d["gt_points"], d["K"], d["c2w"], scene.height, scene.width, d["params"],
                    gt_depth_maps=d["depth"], bbox=d["bbox"], ground_plane=d["plane"], seed=seed)
    out = {"cd": r.chamfer, "acc": r.d2s, "comp": r.s2d}
    return {k: float(v) for k, v in out.items() if np.isfinite(v)}


@register_protocol("llff", LLFFParams)
def evaluate_llff(snapshot: Snapshot, scene: Scene, params: LLFFParams, seed: int) -> dict[str, float]:
    """PSNR and SSIM of the test-view renders (FSGS's split)."""
    from metrics.image import psnr, ssim

    test = scene.view_indices("test")
    return {"psnr": float(psnr(snapshot.renders, scene.images[test]).mean),
            "ssim": float(ssim(snapshot.renders, scene.images[test], padding=params.ssim_padding).mean)}


SUPPORTED_PROTOCOLS = tuple(PROTOCOL_REGISTRY)


def evaluate_snapshot(snapshot: Snapshot, scene: Scene, protocol: str, scale: str, seed: int = 0) -> dict[str, float]:
    """Metrics of one snapshot under a registered protocol.

    Args:
        snapshot: method output (mesh for ``scannet`` / ``replica`` / ``dtu``, renders for ``llff``).
        scene: the evaluated scene (GT mesh, cameras).
        protocol: a name of :data:`PROTOCOL_REGISTRY` (``scannet`` | ``replica`` | ``dtu`` | ``llff``).
        scale: selects the protocol parameters (``configs/protocols.yaml``).
        seed: seed of the point sampling (Replica, DTU).

    Returns:
        ``{metric key: value}``.
    """
    entry = get_protocol(protocol)
    return entry.evaluate(snapshot, scene, protocol_params(protocol, scale), seed)
