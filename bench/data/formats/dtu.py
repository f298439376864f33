"""DTU in the IDR / NeuS layout.

Files of the real format:

=================================  ========  ==========================================================
file                               needed?   content
=================================  ========  ==========================================================
``image/*.png`` (or ``.jpg``)      required  8-bit RGB, sorted by name (we write ``{i:06d}.png``); all
                                             the same size
``cameras.npz``                    required  ``world_mat_i`` = K4 @ world_to_cam and ``scale_mat_i``
(or NeuS ``cameras_sphere.npz``)             (normalised -> world), i = position in sorted order
``mask/*.png``                     optional  object masks (we write ``{i:03d}.png``, 8-bit 0 / 255; IDR's
                                             3-channel masks read too), one per image; read with
                                             :func:`load_object_masks` (Scene has no mask field), checked
                                             for count and size by :func:`load`
=================================  ========  ==========================================================

Our extras (all optional): ``mono_depth/``, ``mono_normal/``, ``gt_depth/``, ``gt_normal/``,
``gt_instance/``, ``seg/`` sub-folders of ``{i:06d}.npy|png`` and the side files ``meta.json``,
``segments.json``, ``instances.json``, ``gt_mesh.ply`` (see :mod:`bench.data.formats.extras`).

The object mask we write = pixels whose GT instance is not background; without GT instances, pixels
with GT depth > 0; without either, every pixel.

Splits: from ``meta.json`` (synthetic scenes: ``train`` = the 3 sparse views, ``eval_only`` = the dense
views used only for the evaluation observation mask). Without meta.json: option ``train_views``
(default the little-overlap set 22, 25, 28 of pixelNeRF / RegNeRF when the scan has > 28 views, else
no splits); ``eval_only`` = every other view. Kind defaults to ``"object"``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Sequence

import numpy as np

from bench.data.errors import BenchInputError
from bench.data.formats import codec, extras
from bench.data.formats.cameras import check_view_numbering
from bench.data.formats.monosdf import read_cameras_npz, write_cameras_npz
from bench.data.scene import Scene

IMAGE_DIR = "image"
MASK_DIR = "mask"
CAMERA_FILES = ("cameras.npz", "cameras_sphere.npz")
DEFAULT_TRAIN_VIEWS = (22, 25, 28)
_IMAGE_EXTS = {".png", ".jpg", ".jpeg"}


def object_masks(scene: Scene) -> np.ndarray:
    """(N, H, W) bool object masks: non-background GT instances, else GT depth > 0, else all True."""
    if scene.gt_instance is not None:
        fg_ids = [k for k, info in scene.instances.items() if not info.is_background]
        if scene.instances:
            return np.isin(scene.gt_instance, fg_ids)
        return scene.gt_instance > 0
    if scene.gt_depth is not None:
        return scene.gt_depth > 0
    return np.ones((scene.num_views, scene.height, scene.width), dtype=bool)


def write(scene: Scene, out_dir: Path, fmt: str = "dtu", gt_mesh: Any = None) -> None:
    """Write ``scene`` in the IDR layout plus our extras in sub-folders."""
    (out_dir / IMAGE_DIR).mkdir()
    (out_dir / MASK_DIR).mkdir()
    masks = object_masks(scene)
    for i in range(scene.num_views):
        codec.write_rgb(out_dir / IMAGE_DIR / f"{i:06d}.png", scene.images[i])
        codec.write_mask(out_dir / MASK_DIR / f"{i:03d}.png", masks[i])
    write_cameras_npz(out_dir / CAMERA_FILES[0], scene)
    prefixes = tuple(f"{i:06d}" for i in range(scene.num_views))
    extras.write_view_maps(scene, extras.Layout(out_dir, prefixes, flat=False))
    extras.write_side_files(scene, out_dir, "dtu", gt_mesh)


def _list_images(folder: Path) -> list[Path]:
    if not folder.is_dir():
        raise BenchInputError(folder, "folder is missing")
    paths = sorted(p for p in folder.iterdir() if p.suffix.lower() in _IMAGE_EXTS)
    if not paths:
        raise BenchInputError(folder, "no .png / .jpg images found")
    return paths


def load_object_masks(root: Path, hw: tuple[int, int] | None = None) -> np.ndarray | None:
    """(N, H, W) bool object masks from ``mask/`` (sorted by name), or None if there is no mask folder."""
    folder = root / MASK_DIR
    if not folder.is_dir():
        return None
    return np.stack([codec.read_mask(p, hw) for p in _list_images(folder)])


def default_splits(n: int, train_views: Sequence[int] | None) -> dict[str, np.ndarray]:
    """Splits for a DTU scan without meta.json: ``train`` and ``eval_only`` (= every other view)."""
    if train_views is None:
        if n <= max(DEFAULT_TRAIN_VIEWS):
            return {}
        train_views = DEFAULT_TRAIN_VIEWS
    train = np.asarray(sorted(int(v) for v in train_views), dtype=np.int64)
    if train.size and (train.min() < 0 or train.max() >= n):
        raise BenchInputError("train_views", f"indices {train.tolist()} outside 0..{n - 1}")
    return {"train": train, "eval_only": np.setdiff1d(np.arange(n, dtype=np.int64), train)}


def load(root: Path, fmt: str = "dtu", train_views: Sequence[int] | None = None) -> Scene:
    """Load an IDR-layout DTU scan (see the module docstring for the files).

    Args:
        root: scan folder. train_views: sparse training views when there is no meta.json.
    """
    image_paths = _list_images(root / IMAGE_DIR)
    n = len(image_paths)
    cam_file = next((root / f for f in CAMERA_FILES if (root / f).is_file()), root / CAMERA_FILES[0])
    check_view_numbering(image_paths, lambda p: p.stem, cam_file.name)
    K, c2w, scale_mat = read_cameras_npz(cam_file, n)

    first = codec.read_rgb(image_paths[0])
    hw = first.shape[:2]
    images = np.stack([first] + [codec.read_rgb(p, hw) for p in image_paths[1:]])
    if (root / MASK_DIR).is_dir():
        mask_paths = _list_images(root / MASK_DIR)
        if len(mask_paths) != n:
            raise BenchInputError(root / MASK_DIR, f"holds {len(mask_paths)} masks for {n} images")
        for p in mask_paths:
            codec.read_mask(p, hw)

    prefixes = tuple(f"{i:06d}" for i in range(n))
    maps = extras.read_view_maps(extras.Layout(root, prefixes, flat=False), hw)
    side = extras.read_side_files(root)
    return extras.build_scene(root, "dtu", "object", images, K, c2w, scale_mat, maps, side, splits=default_splits(n, train_views))
