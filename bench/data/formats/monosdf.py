"""ScanNet / Replica in MonoSDF's preprocessed layout (one flat scene folder).

Files of the real format (what MonoSDF's ``SceneDatasetDN`` reads):

==========================  ========  ===================================================================
file                        needed?   content
==========================  ========  ===================================================================
``cameras.npz``             required  ``world_mat_i`` (4, 4) = K4 @ world_to_cam, ``scale_mat_i`` (4, 4)
                                      normalised -> world, for i = 0..N-1 (i = position in sorted order)
``*_rgb.png``               required  8-bit RGB, sorted by name; N = their number; all the same size
``{prefix}_depth.npy``      optional  mono depth prior (H, W) float32 -> ``Scene.mono_depth``
``{prefix}_normal.npy``     optional  mono normal prior (3, H, W) in [0, 1] -> ``Scene.mono_normal``
``{prefix}_mask.npy``       optional  Replica only: (H, W) valid-mono-depth mask; mono depth is set to 0
                                      (= invalid) where it is false
==========================  ========  ===================================================================

``{prefix}`` is the rgb file name without ``_rgb.png`` (``000000`` when we write). Priors are
all-or-nothing across views. Our extras (GT depth / normal / instances, segments, meta.json, ...) are
listed in :mod:`bench.data.formats.extras`; all optional.

Loading: poses come from MonoSDF's decomposition of ``world_mat_i @ scale_mat_i``, mapped back to world
metres (see :mod:`bench.data.formats.cameras`); matrices are read in float64 (MonoSDF casts to float32).
``Scene.scale_mat`` = ``scale_mat_0``; all ``scale_mat_i`` must be equal. Kind defaults to ``"room"``,
splits to none (every view trains), unless ``meta.json`` says otherwise.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np

from bench.data.errors import BenchInputError
from bench.data.formats import codec, extras
from bench.data.formats.cameras import check_view_numbering, compose_world_mat, decompose_world_mat
from bench.data.formats.npz import load_npy, load_npz, save_npy, save_npz
from bench.data.scene import Scene

CAMERAS_FILE = "cameras.npz"


# ------------------------------------------------------------------------------ cameras.npz (shared with dtu)
def write_cameras_npz(path: Path, scene: Scene) -> None:
    """Write IDR/MonoSDF ``cameras.npz``: ``world_mat_i``, ``scale_mat_i`` (float64) for every view."""
    arrays: dict[str, np.ndarray] = {}
    for i in range(scene.num_views):
        arrays[f"world_mat_{i}"] = compose_world_mat(scene.intrinsics[i], scene.cam_to_world[i])
        arrays[f"scale_mat_{i}"] = np.asarray(scene.scale_mat, dtype=np.float64)
    save_npz(path, arrays)


def read_cameras_npz(path: Path, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Read N cameras from an IDR/MonoSDF ``cameras.npz``.

    Returns:
        K (N, 3, 3) float64 pixels, cam_to_world (N, 4, 4) float64 world metres (OpenCV),
        scale_mat (4, 4) float64 (``scale_mat_0``).
    """
    data = load_npz(path)
    n_cams = len([k for k in data if re.fullmatch(r"world_mat_\d+", k)])
    if n_cams > n:
        raise BenchInputError(path, f"holds {n_cams} cameras (world_mat_*) for {n} images")
    Ks, poses = [], []
    scale_mat0 = None
    for i in range(n):
        for key in (f"world_mat_{i}", f"scale_mat_{i}"):
            if key not in data:
                raise BenchInputError(path, f"{key} is missing ({n} images need world_mat_0..{n - 1})")
        sm = np.asarray(data[f"scale_mat_{i}"], dtype=np.float64)
        K, c2w = decompose_world_mat(data[f"world_mat_{i}"], sm, path, i)
        if scale_mat0 is None:
            scale_mat0 = sm
        elif not np.allclose(sm, scale_mat0, rtol=1e-9, atol=1e-12):
            raise BenchInputError(path, f"scale_mat_{i} differs from scale_mat_0 (one scale_mat per scene)")
        Ks.append(K)
        poses.append(c2w)
    assert scale_mat0 is not None
    return np.stack(Ks), np.stack(poses), scale_mat0


# ------------------------------------------------------------------------------ writer
def write(scene: Scene, out_dir: Path, fmt: str, gt_mesh: Any = None) -> None:
    """Write ``scene`` in MonoSDF's layout (``fmt`` = ``"scannet"`` or ``"replica"``) plus our extras."""
    write_cameras_npz(out_dir / CAMERAS_FILE, scene)
    prefixes = tuple(f"{i:06d}" for i in range(scene.num_views))
    for i, prefix in enumerate(prefixes):
        codec.write_rgb(out_dir / f"{prefix}_rgb.png", scene.images[i])
        if fmt == "replica":
            mask = (
                scene.mono_depth[i] > 0
                if scene.mono_depth is not None
                else np.ones((scene.height, scene.width), dtype=bool)
            )
            save_npy(out_dir / f"{prefix}_mask.npy", mask)
    extras.write_view_maps(scene, extras.Layout(out_dir, prefixes, flat=True))
    extras.write_side_files(scene, out_dir, fmt, gt_mesh)


# ------------------------------------------------------------------------------ loader
def load(root: Path, fmt: str) -> Scene:
    """Load a MonoSDF-layout ScanNet / Replica folder (see the module docstring for the files)."""
    rgb_paths = sorted(root.glob("*_rgb.png"))
    if not rgb_paths:
        raise BenchInputError(root, "no *_rgb.png images found")
    prefixes = tuple(p.name[: -len("_rgb.png")] for p in rgb_paths)
    n = len(rgb_paths)
    check_view_numbering(rgb_paths, lambda p: p.name[: -len("_rgb.png")], CAMERAS_FILE)
    K, c2w, scale_mat = read_cameras_npz(root / CAMERAS_FILE, n)

    first = codec.read_rgb(rgb_paths[0])
    hw = first.shape[:2]
    images = np.stack([first] + [codec.read_rgb(p, hw) for p in rgb_paths[1:]])

    maps = extras.read_view_maps(extras.Layout(root, prefixes, flat=True), hw)
    if fmt == "replica":
        mask_paths = [root / f"{p}_mask.npy" for p in prefixes]
        present = [p.is_file() for p in mask_paths]
        if any(present) and not all(present):
            raise BenchInputError(mask_paths[present.index(False)], "file is missing (masks exist for other views)")
        if all(present) and maps["mono_depth"] is not None:
            for i, p in enumerate(mask_paths):
                mask = load_npy(p)
                if mask.shape != hw:
                    raise BenchInputError(p, f"mask has shape {mask.shape}, expected {hw}")
                codec.check_finite(p, mask)
                maps["mono_depth"][i][~(mask > 0)] = 0.0

    side = extras.read_side_files(root)
    return extras.build_scene(root, fmt, "room", images, K, c2w, scale_mat, maps, side)
