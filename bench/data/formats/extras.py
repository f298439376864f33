"""Our additions to the real formats: GT / segmentation per-view maps and the JSON side files.

None of these files exists in a real preprocessed dataset; every loader treats them as optional (the
Scene field is None / empty when absent). Per-view maps come in two layouts:

* ``flat`` (ScanNet / Replica, beside MonoSDF's files): ``{prefix}_{suffix}`` in the scene folder,
  prefix = the view's ``{i:06d}``;
* ``folders`` (DTU, LLFF): ``{kind}/{i:06d}.{ext}`` sub-folders.

=============  ==========================  =====================  =======================================
Scene field    flat file                   folder file            content
=============  ==========================  =====================  =======================================
mono_depth     ``{i:06d}_depth.npy`` (*)   ``mono_depth/*.npy``   (H, W) float32, 0 = invalid
mono_normal    ``{i:06d}_normal.npy`` (*)  ``mono_normal/*.npy``  (3, H, W) float32 in [0, 1], n*0.5+0.5
gt_depth       ``{i:06d}_gt_depth.npy``    ``gt_depth/*.npy``     (H, W) float32 z-depth metres, 0 = none
gt_normal      ``{i:06d}_gt_normal.npy``   ``gt_normal/*.npy``    (H, W, 3) float32 unit, OpenCV cam frame
gt_instance    ``{i:06d}_gt_instance.png`` ``gt_instance/*.png``  16-bit grey, GT instance id, 0 = none
seg_masks      ``{i:06d}_seg.png``         ``seg/*.png``          16-bit grey, per-view segment id
=============  ==========================  =====================  =======================================

(*) part of MonoSDF's real layout, not an extra there.

Side files (both layouts, in the scene folder):

* ``segments.json``: ``{"views": [{"<segment id>": is_background, ...}, ...]}`` one dict per view.
* ``instances.json``: ``{"instances": [InstanceInfo.to_dict(), ...]}`` sorted by id.
* ``gt_mesh.ply``: GT mesh in world metres (binary PLY written by trimesh).
* ``meta.json``: ``{"format_version", "name", "kind", "format", "num_views", "height", "width",
  "splits": {name: [indices]}, "scale_mat": 4x4 list, "metadata": {... effects applied ...}}``.

A kind is all-or-nothing: if a file of it exists for one view it must exist for every view.
"""

from __future__ import annotations

import json
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, cast

import numpy as np

from bench.data.atomic import dumps_json
from bench.data.errors import BenchInputError
from bench.data.formats import codec
from bench.data.scene import InstanceInfo, Scene

META_FILE = "meta.json"
SEGMENTS_FILE = "segments.json"
INSTANCES_FILE = "instances.json"
GT_MESH_FILE = "gt_mesh.ply"

# kind -> (flat suffix, folder extension, Scene field)
_KINDS: dict[str, tuple[str, str, str]] = {
    "mono_depth": ("depth.npy", "npy", "mono_depth"),
    "mono_normal": ("normal.npy", "npy", "mono_normal"),
    "gt_depth": ("gt_depth.npy", "npy", "gt_depth"),
    "gt_normal": ("gt_normal.npy", "npy", "gt_normal"),
    "gt_instance": ("gt_instance.png", "png", "gt_instance"),
    "seg": ("seg.png", "png", "seg_masks"),
}

_WRITERS: dict[str, Callable[[Path, np.ndarray], None]] = {
    "mono_depth": codec.write_depth,
    "mono_normal": codec.write_mono_normal,
    "gt_depth": codec.write_depth,
    "gt_normal": codec.write_gt_normal,
    "gt_instance": codec.write_ids16,
    "seg": codec.write_ids16,
}

_READERS: dict[str, Callable[[Path, tuple[int, int] | None], np.ndarray]] = {
    "mono_depth": codec.read_depth,
    "mono_normal": codec.read_mono_normal,
    "gt_depth": codec.read_depth,
    "gt_normal": codec.read_gt_normal,
    "gt_instance": codec.read_ids16,
    "seg": codec.read_ids16,
}


@dataclass(frozen=True)
class Layout:
    """Where per-view maps live. ``prefixes[i]`` names view i (``{i:06d}``, or the stem of a real file)."""

    root: Path
    prefixes: tuple[str, ...]
    flat: bool

    def path(self, kind: str, i: int) -> Path:
        suffix, ext, _ = _KINDS[kind]
        if self.flat:
            return self.root / f"{self.prefixes[i]}_{suffix}"
        return self.root / kind / f"{self.prefixes[i]}.{ext}"


def write_view_maps(scene: Scene, layout: Layout, kinds: tuple[str, ...] = tuple(_KINDS)) -> None:
    """Write every present per-view map of ``scene`` among ``kinds``."""
    for kind in kinds:
        arr = getattr(scene, _KINDS[kind][2])
        if arr is None:
            continue
        if not layout.flat:
            (layout.root / kind).mkdir(exist_ok=True)
        for i in range(scene.num_views):
            _WRITERS[kind](layout.path(kind, i), arr[i])


def read_view_maps(
    layout: Layout, hw: tuple[int, int], kinds: tuple[str, ...] = tuple(_KINDS)
) -> dict[str, np.ndarray | None]:
    """Read each kind as a stacked (N, H, W[, 3]) array, or None if no view has it (Scene field names)."""
    out: dict[str, np.ndarray | None] = {}
    n = len(layout.prefixes)
    for kind in kinds:
        paths = [layout.path(kind, i) for i in range(n)]
        present = [p.is_file() for p in paths]
        field = _KINDS[kind][2]
        if not any(present):
            out[field] = None
            continue
        if not all(present):
            raise BenchInputError(paths[present.index(False)], f"file is missing ({kind} exists for other views)")
        out[field] = np.stack([_READERS[kind](p, hw) for p in paths])
    return out


# ------------------------------------------------------------------------------ JSON side files
def read_json(path: Path) -> Any:
    """Parse a JSON file; BenchInputError if missing or malformed."""
    if not path.is_file():
        raise BenchInputError(path, "file is missing")
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise BenchInputError(path, f"not valid JSON ({e})") from None


def write_side_files(scene: Scene, root: Path, fmt: str, gt_mesh: Any = None) -> None:
    """Write ``meta.json``, ``segments.json``, ``instances.json`` and ``gt_mesh.ply`` (those that apply).

    The GT mesh is ``gt_mesh`` if given, else a byte copy of ``scene.gt_mesh_path`` if that exists.
    """
    meta = {
        "format_version": 1,
        "name": scene.name,
        "kind": scene.kind,
        "format": fmt,
        "num_views": scene.num_views,
        "height": scene.height,
        "width": scene.width,
        "splits": {k: [int(x) for x in np.asarray(v).ravel()] for k, v in scene.splits.items()},
        "scale_mat": np.asarray(scene.scale_mat, dtype=np.float64).tolist(),
        "metadata": scene.metadata,
    }
    (root / META_FILE).write_text(dumps_json(meta), encoding="utf-8")
    if scene.seg_background is not None:
        views = [{str(int(k)): bool(v) for k, v in d.items()} for d in scene.seg_background]
        (root / SEGMENTS_FILE).write_text(dumps_json({"views": views}), encoding="utf-8")
    if scene.instances:
        table = [scene.instances[k].to_dict() for k in sorted(scene.instances)]
        (root / INSTANCES_FILE).write_text(dumps_json({"instances": table}), encoding="utf-8")
    if gt_mesh is not None:
        data = gt_mesh.export(file_type="ply", encoding="binary")
        (root / GT_MESH_FILE).write_bytes(data if isinstance(data, bytes) else data.encode())
    elif scene.gt_mesh_path is not None and Path(scene.gt_mesh_path).is_file():
        shutil.copyfile(scene.gt_mesh_path, root / GT_MESH_FILE)


@dataclass
class SideFiles:
    """Contents of the optional side files (defaults when absent)."""

    meta: dict[str, Any] | None
    seg_background: list[dict[int, bool]] | None
    instances: dict[int, InstanceInfo]
    gt_mesh_path: Path | None


def read_side_files(root: Path) -> SideFiles:
    """Read the optional side files of a dataset folder; malformed content raises BenchInputError."""
    meta = None
    if (root / META_FILE).is_file():
        meta = read_json(root / META_FILE)
        if not isinstance(meta, dict):
            raise BenchInputError(root / META_FILE, "expected a JSON object")
    seg_background = None
    if (root / SEGMENTS_FILE).is_file():
        path = root / SEGMENTS_FILE
        data = read_json(path)
        try:
            seg_background = [{int(k): bool(v) for k, v in d.items()} for d in data["views"]]
        except (KeyError, TypeError, ValueError, AttributeError) as e:
            raise BenchInputError(path, f"expected {{'views': [{{segment id: is_background}}, ...]}} ({e})") from None
    instances: dict[int, InstanceInfo] = {}
    if (root / INSTANCES_FILE).is_file():
        path = root / INSTANCES_FILE
        data = read_json(path)
        try:
            for d in data["instances"]:
                info = InstanceInfo.from_dict(d)
                instances[info.instance_id] = info
        except (KeyError, TypeError, ValueError) as e:
            raise BenchInputError(path, f"malformed instance table ({type(e).__name__}: {e})") from None
    mesh = root / GT_MESH_FILE
    if mesh.is_file():
        check_gt_mesh(mesh)
    return SideFiles(meta, seg_background, instances, mesh if mesh.is_file() else None)


def check_gt_mesh(path: Path) -> None:
    """A readable triangle mesh with finite vertices and faces that index them (a truncated or corrupt
    ``gt_mesh.ply`` fails here, naming the file, not at evaluation time)."""
    import trimesh

    try:
        mesh = cast(trimesh.Trimesh, trimesh.load(path, force="mesh", process=False))
    except Exception as exc:  # trimesh raises ValueError / KeyError / struct errors on broken files
        raise BenchInputError(path, f"GT mesh cannot be read ({type(exc).__name__}: {exc})") from None
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    if len(v) == 0 or len(f) == 0:
        raise BenchInputError(path, f"GT mesh is empty ({len(v)} vertices, {len(f)} faces)")
    if not np.isfinite(v).all():
        raise BenchInputError(path, "GT mesh has NaN or inf vertices")
    if f.min() < 0 or f.max() >= len(v):
        raise BenchInputError(path, f"GT mesh faces index vertex {int(f.max())} of {len(v)}")


def meta_splits(meta: dict[str, Any], where: Path, num_views: int) -> dict[str, np.ndarray]:
    """``meta["splits"]`` as int64 index arrays, checked to lie in [0, num_views)."""
    out: dict[str, np.ndarray] = {}
    for name, idx in dict(meta.get("splits", {})).items():
        arr = np.asarray(idx, dtype=np.int64).ravel()
        if arr.size and (arr.min() < 0 or arr.max() >= num_views):
            raise BenchInputError(where, f"split {name!r} has indices outside 0..{num_views - 1}")
        out[str(name)] = arr
    return out


def meta_scale_mat(meta: dict[str, Any], where: Path) -> np.ndarray | None:
    """``meta["scale_mat"]`` as (4, 4) float64, or None if absent."""
    if "scale_mat" not in meta:
        return None
    sm = np.asarray(meta["scale_mat"], dtype=np.float64)
    if sm.shape != (4, 4) or not np.all(np.isfinite(sm)):
        raise BenchInputError(where, f"scale_mat must be a finite 4x4 matrix, got shape {sm.shape}")
    return sm


def build_scene(root: Path, fmt: str, kind: str, images: np.ndarray, K: np.ndarray, c2w: np.ndarray, scale_mat: np.ndarray,
                maps: dict[str, Any], side: SideFiles, splits: dict[str, np.ndarray] | None = None,
                metadata_extra: dict[str, Any] | None = None) -> "Scene":
    """The one place every loader turns what it read into a validated :class:`Scene`: the format's own
    arrays, our optional per-view maps and side files, then meta.json (name / kind / splits / metadata)."""
    from bench.data.scene import Scene

    kwargs: dict[str, Any] = dict(name=root.name, kind=kind, source_format=fmt, images=images, intrinsics=K, cam_to_world=c2w,
                                  scale_mat=scale_mat, seg_background=side.seg_background, instances=side.instances,
                                  gt_mesh_path=side.gt_mesh_path, root=root, metadata={}, **maps)
    if splits is not None:
        kwargs["splits"] = splits
    apply_meta(kwargs, side, root, fmt)
    if metadata_extra:
        kwargs["metadata"] = dict(kwargs["metadata"], **metadata_extra)
    scene = Scene(**kwargs)
    scene.validate()
    return scene


def apply_meta(scene_kwargs: dict[str, Any], side: SideFiles, root: Path, fmt: str) -> None:
    """Fill name / kind / splits / metadata from meta.json (if present) into Scene keyword arguments."""
    meta = side.meta
    if meta is None:
        return
    where = root / META_FILE
    if "format" in meta and meta["format"] != fmt and {meta["format"], fmt} != {"scannet", "replica"}:
        raise BenchInputError(where, f"format is {meta['format']!r} but the folder is loaded as {fmt!r}")
    scene_kwargs["name"] = str(meta.get("name", scene_kwargs["name"]))
    scene_kwargs["kind"] = str(meta.get("kind", scene_kwargs["kind"]))
    scene_kwargs["metadata"] = dict(meta.get("metadata", {}))
    n = scene_kwargs["images"].shape[0]
    if "num_views" in meta and int(meta["num_views"]) != n:
        raise BenchInputError(where, f"num_views is {meta['num_views']} but the folder holds {n} views")
    if "splits" in meta:
        scene_kwargs["splits"] = meta_splits(meta, where, n)
