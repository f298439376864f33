"""Evaluation of one method snapshot under a table's protocol (the only place that maps protocols to metrics).

Metric keys produced (the table specs' column keys): ``acc``, ``comp``, ``cd`` (metres), ``prec``,
``recall``, ``fscore`` (fractions at the protocol threshold, 5 cm), ``nc`` (Replica only); ``psnr`` (dB),
``ssim`` for image protocols. Protocol parameters live in ``configs/protocols.yaml`` (per scale).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import yaml

from bench.errors import BenchInputError
from bench.scene import Scene
from methods.base import Snapshot

PROTOCOLS_FILE = Path(__file__).resolve().parent.parent / "configs" / "protocols.yaml"
SUPPORTED_PROTOCOLS = ("scannet", "replica", "llff")
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


_GT_CACHE: dict[tuple, Any] = {}  # GT-side work per scene: identical for every snapshot of a job


def _refused_gt(scene: Scene, views: np.ndarray, params: dict[str, Any]) -> Any:
    from metrics.culling import tsdf_refuse

    key = (str(scene.root or scene.name), tuple(int(v) for v in views), tuple(sorted(params.items())))
    if key not in _GT_CACHE:
        if len(_GT_CACHE) > 4:
            _GT_CACHE.clear()
        _GT_CACHE[key] = tsdf_refuse(scene.load_gt_mesh(), scene.intrinsics[views], scene.cam_to_world[views], scene.height, scene.width,
                                     voxel_size=params["tsdf_voxel"], sdf_trunc=params["tsdf_trunc"], depth_trunc=params["depth_trunc"])
    return _GT_CACHE[key]


def _replica_gt(scene: Scene, views: np.ndarray, params: dict[str, Any], seed: int) -> Any:
    from metrics.protocols import prepare_replica_gt

    key = ("replica", str(scene.root or scene.name), tuple(int(v) for v in views), tuple(sorted(params.items())), seed)
    if key not in _GT_CACHE:
        if len(_GT_CACHE) > 4:
            _GT_CACHE.clear()
        gt_params = {k: v for k, v in params.items() if k != "threshold"}
        _GT_CACHE[key] = prepare_replica_gt(scene.load_gt_mesh(), scene.intrinsics[views], scene.cam_to_world[views],
                                            scene.height, scene.width, seed=seed, **gt_params)
    return _GT_CACHE[key]


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
            gt = _refused_gt(scene, views, params)
            return _mesh_metrics(evaluate_mesh_scannet(snapshot.mesh, gt, *cams, refuse_gt=False, **params))
        prepared = _replica_gt(scene, views, params, seed)
        return _mesh_metrics(evaluate_mesh_replica(snapshot.mesh, None, *cams, seed=seed, prepared_gt=prepared, **params))
    if protocol == "llff":
        from metrics.image import psnr, ssim

        test = scene.view_indices("test")
        return {"psnr": float(psnr(snapshot.renders, scene.images[test]).mean), "ssim": float(ssim(snapshot.renders, scene.images[test]).mean)}
    raise BenchInputError(f"protocol {protocol!r}", f"not supported by the evaluator yet {SUPPORTED_PROTOCOLS}")
