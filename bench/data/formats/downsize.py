"""``bench scenes downsize SRC DST --factor N``: a dataset folder at 1/N of its image size, same format.

How real ScanNet / Replica / DTU / LLFF data is brought to CPU scale (MonoSDF's 384 x 384 ScanNet frames
at ``--factor 3`` are 128 x 128). Every per-view map is resampled by the block of N x N source pixels
that becomes one target pixel; images whose size is not a multiple of N lose the last rows / columns
(the principal point is unchanged by that crop):

* RGB: the block mean (area averaging, what ``cv2.INTER_AREA`` does for an integer factor);
* depth (prior and GT): the block median of the valid (> 0) values, 0 when fewer than half are valid
  (a mean would invent depths between a foreground edge and the background behind it);
* normals: the block mean of the valid unit vectors, renormalised (0 where none is valid);
* instance / segment ids: the id at the block's centre pixel (ids cannot be averaged);
* intrinsics, pixel-centre convention (pixel u covers [u - 0.5, u + 0.5]): ``f' = f / N``,
  ``c' = (c + 0.5) / N - 0.5``.

Poses, the normalisation, the GT mesh, splits, instance tables and metadata are copied unchanged. The
target is written atomically (complete or absent).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from bench.data.errors import BenchInputError
from bench.data.scene import Scene


def _blocks(arr: np.ndarray, n: int) -> np.ndarray:
    """(V, H, W, ...) -> (V, H // n, W // n, n * n, ...): the n x n source block of every target pixel."""
    v, h, w = arr.shape[:3]
    h2, w2 = h // n, w // n
    a = arr[:, : h2 * n, : w2 * n]
    a = a.reshape(v, h2, n, w2, n, *arr.shape[3:])
    a = np.moveaxis(a, 2, 3)  # (V, h2, w2, n, n, ...)
    return a.reshape(v, h2, w2, n * n, *arr.shape[3:])


def downsize_rgb(images: np.ndarray, n: int) -> np.ndarray:
    return _blocks(images.astype(np.float32), n).mean(axis=3).astype(np.float32)


def downsize_depth(depth: np.ndarray, n: int) -> np.ndarray:
    b = _blocks(depth.astype(np.float32), n)
    valid = b > 0
    keep = valid.sum(axis=3) * 2 >= n * n
    med = np.zeros(b.shape[:3], np.float32)
    if keep.any():  # the median only where at least half the block is valid (no all-NaN blocks)
        med[keep] = np.nanmedian(np.where(valid[keep], b[keep], np.nan), axis=1)
    return np.where(keep, np.nan_to_num(med), 0.0).astype(np.float32)


def downsize_normal(normal: np.ndarray, n: int) -> np.ndarray:
    b = _blocks(normal.astype(np.float32), n)
    s = b.sum(axis=3)
    norm = np.linalg.norm(s, axis=-1, keepdims=True)
    return np.where(norm > 1e-6, s / np.maximum(norm, 1e-6), 0.0).astype(np.float32)


def downsize_ids(ids: np.ndarray, n: int) -> np.ndarray:
    c = (n // 2) * n + n // 2  # the block's centre pixel (row n // 2, column n // 2)
    return _blocks(ids, n)[:, :, :, c].astype(ids.dtype)


def downsize_intrinsics(K: np.ndarray, n: int) -> np.ndarray:
    out = np.array(K, dtype=np.float64, copy=True)
    out[..., 0, 0] /= n
    out[..., 1, 1] /= n
    out[..., 0, 1] /= n
    out[..., 0, 2] = (out[..., 0, 2] + 0.5) / n - 0.5
    out[..., 1, 2] = (out[..., 1, 2] + 0.5) / n - 0.5
    return out


def downsize_scene(scene: Scene, n: int) -> Scene:
    """``scene`` at 1 / ``n`` of its image size (see the module docstring for each map)."""
    if n < 1 or scene.height // n < 8 or scene.width // n < 8:
        raise BenchInputError(scene.root or scene.name, f"--factor {n} leaves {scene.width // max(n, 1)} x "
                              f"{scene.height // max(n, 1)} px (need a factor >= 1 and >= 8 px per side)")

    def opt(arr, fn):
        return None if arr is None else fn(arr, n)

    return dataclasses.replace(
        scene, images=downsize_rgb(scene.images, n), intrinsics=downsize_intrinsics(scene.intrinsics, n),
        mono_depth=opt(scene.mono_depth, downsize_depth), mono_normal=opt(scene.mono_normal, downsize_normal),
        seg_masks=opt(scene.seg_masks, downsize_ids), gt_depth=opt(scene.gt_depth, downsize_depth),
        gt_normal=opt(scene.gt_normal, downsize_normal), gt_instance=opt(scene.gt_instance, downsize_ids))


def downsize_folder(src: Path, dst: Path, n: int, overwrite: bool = False) -> Scene:
    """Load ``src`` (any format), write it at 1 / ``n`` into ``dst`` in the same format; returns the result."""
    from bench.data.atomic import atomic_directory
    from bench.data.formats import detect_format, load_scene, write_scene

    fmt = detect_format(Path(src))
    small = downsize_scene(load_scene(Path(src), fmt), n)
    with atomic_directory(dst, overwrite=overwrite) as tmp:
        write_scene(small, tmp, fmt)
    return small
