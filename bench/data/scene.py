"""The one typed scene object every loader returns and every method consumes.

Camera convention (used everywhere in the project, whatever the on-disk format):

* ``cam_to_world`` is a (4, 4) float64 matrix mapping camera coordinates to world coordinates.
* Camera axes follow OpenCV: x right, y down, z forward (the camera looks along +z).
* World units are metres.
* Pixel (row v, column u) has its centre at image coordinates (u, v) (OpenCV: integer centres), so
  the ray through it is ``cam_to_world[:3, :3] @ inv(K) @ [u, v, 1]``.
* Depth maps are z-depth (distance along the optical axis), not Euclidean ray length; 0 means "no
  surface / invalid".
* Normal maps are unit vectors in the camera frame (OpenCV axes), oriented towards the camera.

Formats stop at the loaders (``bench/data/formats``): a method sees only :class:`Scene`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

SCENE_KINDS = ("room", "object", "forward")
DATASET_FORMATS = ("scannet", "replica", "dtu", "llff")


@dataclass(frozen=True)
class InstanceInfo:
    """One ground-truth object instance of a synthetic scene.

    Attributes:
        instance_id: GT id (>= 1), consistent across views (0 is reserved for "no surface").
        name: unique readable name, e.g. ``"chair_0"`` or ``"wall_north"``.
        category: class name, e.g. ``"chair"``, ``"table"``, ``"wall"``, ``"floor"``.
        is_background: True for wall / floor / ceiling (the classes MonoInstance's text-prompted
            detector flags as background; they get uncertainty 0).
        is_thin: True if the instance has thin parts (legs, poles, stems, wires).
    """

    instance_id: int
    name: str
    category: str
    is_background: bool
    is_thin: bool

    def to_dict(self) -> dict[str, Any]:
        return {
            "instance_id": int(self.instance_id),
            "name": self.name,
            "category": self.category,
            "is_background": bool(self.is_background),
            "is_thin": bool(self.is_thin),
        }

    @staticmethod
    def from_dict(d: dict[str, Any]) -> "InstanceInfo":
        return InstanceInfo(
            instance_id=int(d["instance_id"]),
            name=str(d["name"]),
            category=str(d["category"]),
            is_background=bool(d["is_background"]),
            is_thin=bool(d["is_thin"]),
        )


@dataclass
class Scene:
    """A multi-view scene with priors and (for synthetic scenes) ground truth.

    N views of H x W pixels. All per-view arrays share the first axis N. Optional fields are None
    when the source does not provide them (a real preprocessed dataset has no GT instance ids).

    Attributes:
        name: scene name (e.g. ``"scannet_like_0"``).
        kind: one of ``SCENE_KINDS``: ``"room"`` (indoor), ``"object"`` (DTU-like), ``"forward"`` (LLFF-like).
        source_format: on-disk format it was loaded from, one of ``DATASET_FORMATS``.
        images: (N, H, W, 3) float32 RGB in [0, 1] (8-bit values / 255, as stored).
        intrinsics: (N, 3, 3) float64 pinhole K in pixels.
        cam_to_world: (N, 4, 4) float64 camera-to-world, OpenCV axes, metres.
        mono_depth: (N, H, W) float32 monocular depth prior (z-depth up to an unknown per-view
            scale/shift), 0 = invalid.
        mono_normal: (N, H, W, 3) float32 monocular normal prior, unit, camera frame.
        seg_masks: (N, H, W) int32 per-view instance segmentation (0 = unsegmented). Ids are local
            to each view: the same object may carry different ids in different views.
        seg_background: per view, a dict segment id -> True if that segment is background
            (wall / floor / ceiling), standing in for the paper's text-prompted detector.
        gt_depth: (N, H, W) float32 GT z-depth in metres, 0 = no surface.
        gt_normal: (N, H, W, 3) float32 GT normals, unit, camera frame (0 where no surface).
        gt_instance: (N, H, W) int32 GT instance ids consistent across views (0 = no surface).
        instances: GT instance table, id -> :class:`InstanceInfo`.
        gt_mesh_path: path of the GT mesh (world metres) if present; load with ``load_gt_mesh``.
        scale_mat: (4, 4) float64 normalisation: ``x_world = scale_mat @ x_normalised``; maps the
            unit sphere onto the region of interest (MonoSDF / IDR convention).
        splits: index arrays, e.g. ``"train"``, ``"test"`` (LLFF), ``"eval_only"`` (DTU dense views
            used only for the evaluation observation mask).
        metadata: free-form provenance: recipe, seed, the effects applied and their parameters.
        root: dataset folder it was loaded from, if any.
    """

    name: str
    kind: str
    source_format: str
    images: np.ndarray
    intrinsics: np.ndarray
    cam_to_world: np.ndarray
    scale_mat: np.ndarray
    mono_depth: np.ndarray | None = None
    mono_normal: np.ndarray | None = None
    seg_masks: np.ndarray | None = None
    seg_background: list[dict[int, bool]] | None = None
    gt_depth: np.ndarray | None = None
    gt_normal: np.ndarray | None = None
    gt_instance: np.ndarray | None = None
    instances: dict[int, InstanceInfo] = field(default_factory=dict)
    gt_mesh_path: Path | None = None
    splits: dict[str, np.ndarray] = field(default_factory=dict)
    metadata: dict[str, Any] = field(default_factory=dict)
    root: Path | None = None

    # ------------------------------------------------------------------ basic properties
    @property
    def num_views(self) -> int:
        return int(self.images.shape[0])

    @property
    def height(self) -> int:
        return int(self.images.shape[1])

    @property
    def width(self) -> int:
        return int(self.images.shape[2])

    @property
    def metres_per_unit(self) -> float:
        """World metres per normalised unit: the scale of ``scale_mat`` (cube root of |det| of its 3 x 3 part)."""
        return float(np.cbrt(abs(np.linalg.det(np.asarray(self.scale_mat, dtype=np.float64)[:3, :3]))))

    def view_indices(self, split: str = "train") -> np.ndarray:
        """Indices of the views in ``split``; all views if the scene defines no such split."""
        if split in self.splits:
            return np.asarray(self.splits[split], dtype=np.int64)
        return np.arange(self.num_views, dtype=np.int64)

    def world_to_cam(self) -> np.ndarray:
        """(N, 4, 4) float64 world-to-camera matrices."""
        return np.linalg.inv(self.cam_to_world)

    def load_gt_mesh(self):  # -> trimesh.Trimesh
        """Load the GT mesh (world metres) with trimesh; raises BenchInputError if absent."""
        from bench.data.errors import BenchInputError

        if self.gt_mesh_path is None or not Path(self.gt_mesh_path).exists():
            raise BenchInputError(self.gt_mesh_path or self.name, "scene has no GT mesh")
        import trimesh

        return trimesh.load(self.gt_mesh_path, force="mesh", process=False)

    def validate(self) -> None:
        """Check shapes, dtypes and finiteness of every present field; raise ValueError naming the field."""
        n, h, w = self.num_views, self.height, self.width
        where = self.root or self.name

        def check(name: str, arr: np.ndarray | None, shape: tuple[int, ...]) -> None:
            if arr is None:
                return
            if tuple(arr.shape) != shape:
                from bench.data.errors import BenchInputError

                raise BenchInputError(where, f"{name} has shape {tuple(arr.shape)}, expected {shape}")
            if np.issubdtype(arr.dtype, np.floating) and not np.all(np.isfinite(arr)):
                from bench.data.errors import BenchInputError

                raise BenchInputError(where, f"{name} contains NaN or inf")

        check("images", self.images, (n, h, w, 3))
        check("intrinsics", self.intrinsics, (n, 3, 3))
        check("cam_to_world", self.cam_to_world, (n, 4, 4))
        check("scale_mat", self.scale_mat, (4, 4))
        check("mono_depth", self.mono_depth, (n, h, w))
        check("mono_normal", self.mono_normal, (n, h, w, 3))
        check("seg_masks", self.seg_masks, (n, h, w))
        check("gt_depth", self.gt_depth, (n, h, w))
        check("gt_normal", self.gt_normal, (n, h, w, 3))
        check("gt_instance", self.gt_instance, (n, h, w))
        if self.seg_background is not None and len(self.seg_background) != n:
            from bench.data.errors import BenchInputError

            raise BenchInputError(where, f"seg_background has {len(self.seg_background)} views, expected {n}")
