"""Per-pixel file codecs shared by every format: RGB PNGs, 16-bit id PNGs, masks, depth and normal maps.

Readers check what they read and raise :class:`BenchInputError` naming the file and the problem
(missing, unreadable, wrong shape, NaN / inf). Writers are deterministic (PIL writes no timestamp
chunk into PNGs; ``.npy`` has none).

Storage conventions:

* RGB: 8-bit PNG; float [0, 1] images are quantised with ``round(clip(x, 0, 1) * 255)``.
* Ids (GT instances, segments): 16-bit grey PNG, values 0..65535.
* Object masks: 8-bit grey PNG, 0 / 255 (read back as ``value > 127`` on the first channel, so IDR's
  3-channel masks load too).
* Depth: ``.npy`` (H, W) float32. ``(1, H, W)`` and ``(H, W, 1)`` are accepted on read.
* Mono normals, MonoSDF style: ``.npy`` (3, H, W) float32 in [0, 1], ``n * 0.5 + 0.5``, in the OpenCV
  camera frame (x right, y down, z forward). MonoSDF decodes them with ``x * 2 - 1`` and compares them
  with rendered normals rotated into the camera frame of the pose it decomposed from ``world_mat``,
  which is an OpenCV camera (``load_K_Rt_from_P``); so MonoSDF's camera frame *is* OpenCV's and no axis
  flip is made. On read the vectors are renormalised to unit length (zero vectors stay zero).
* GT normals: ``.npy`` (H, W, 3) float32 unit vectors, OpenCV camera frame, stored as is (lossless).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image

from bench.data.errors import BenchInputError
from bench.data.formats.npz import load_npy, save_npy


def _open_image(path: Path) -> Image.Image:
    if not path.is_file():
        raise BenchInputError(path, "file is missing")
    try:
        img = Image.open(path)
        img.load()
        return img
    except Exception as e:
        raise BenchInputError(path, f"not a readable image ({type(e).__name__}: {e})") from None


def check_finite(path: Path, arr: np.ndarray) -> None:
    """BenchInputError if a float array holds NaN or inf."""
    if np.issubdtype(arr.dtype, np.floating):
        if np.isnan(arr).any():
            raise BenchInputError(path, "contains NaN")
        if np.isinf(arr).any():
            raise BenchInputError(path, "contains inf")


def check_size(path: Path, hw: tuple[int, int], expected: tuple[int, int] | None) -> None:
    """BenchInputError if ``hw`` (H, W) differs from ``expected`` (when given)."""
    if expected is not None and tuple(hw) != tuple(expected):
        raise BenchInputError(
            path, f"size {hw[1]}x{hw[0]} (WxH) differs from the images' {expected[1]}x{expected[0]}"
        )


# ---------------------------------------------------------------------------------------- RGB
def quantise_rgb(image: np.ndarray) -> np.ndarray:
    """(H, W, 3) float [0, 1] -> (H, W, 3) uint8."""
    return np.round(np.clip(image, 0.0, 1.0) * 255.0).astype(np.uint8)


def write_rgb(path: Path, image: np.ndarray) -> None:
    """Write an (H, W, 3) float [0, 1] image as an 8-bit RGB PNG."""
    Image.fromarray(quantise_rgb(image), mode="RGB").save(path, format="PNG")


def write_rgb_uint8(path: Path, image: np.ndarray) -> None:
    """Write an (H, W, 3) uint8 image as an 8-bit RGB PNG."""
    Image.fromarray(np.ascontiguousarray(image, dtype=np.uint8), mode="RGB").save(path, format="PNG")


def read_rgb(path: Path, expected_hw: tuple[int, int] | None = None) -> np.ndarray:
    """Read an 8-bit RGB(A)/grey image as (H, W, 3) float32 in [0, 1] (alpha dropped)."""
    img = _open_image(path)
    if img.mode not in ("RGB", "RGBA", "L", "P"):
        raise BenchInputError(path, f"unsupported image mode {img.mode!r} (need 8-bit RGB)")
    arr = np.asarray(img.convert("RGB"), dtype=np.uint8)
    check_size(path, arr.shape[:2], expected_hw)
    return arr.astype(np.float32) / np.float32(255.0)


# ---------------------------------------------------------------------------------------- ids / masks
def write_ids16(path: Path, ids: np.ndarray) -> None:
    """Write an (H, W) integer id map (0..65535) as a 16-bit grey PNG."""
    ids = np.asarray(ids)
    if ids.size and (ids.min() < 0 or ids.max() > 65535):
        raise BenchInputError(path, f"ids must lie in 0..65535 for a 16-bit PNG, got {ids.min()}..{ids.max()}")
    Image.fromarray(np.ascontiguousarray(ids, dtype=np.uint16)).save(path, format="PNG")


def read_ids16(path: Path, expected_hw: tuple[int, int] | None = None) -> np.ndarray:
    """Read a 16-bit (or 8-bit) grey id PNG as (H, W) int32."""
    img = _open_image(path)
    if img.mode not in ("I;16", "I", "L", "I;16B", "I;16L"):
        raise BenchInputError(path, f"id image must be single-channel 8/16-bit, got mode {img.mode!r}")
    arr = np.asarray(img).astype(np.int32)
    check_size(path, arr.shape[:2], expected_hw)
    return arr


def write_mask(path: Path, mask: np.ndarray) -> None:
    """Write an (H, W) bool mask as an 8-bit grey PNG, 0 / 255."""
    Image.fromarray(np.where(np.asarray(mask, dtype=bool), 255, 0).astype(np.uint8), mode="L").save(path, format="PNG")


def read_mask(path: Path, expected_hw: tuple[int, int] | None = None) -> np.ndarray:
    """Read an object-mask PNG (grey or RGB, 0 / 255) as (H, W) bool (first channel > 127)."""
    arr = np.asarray(_open_image(path))
    if arr.ndim == 3:
        arr = arr[..., 0]
    check_size(path, arr.shape[:2], expected_hw)
    return arr > 127


# ---------------------------------------------------------------------------------------- depth
def write_depth(path: Path, depth: np.ndarray) -> None:
    """Write an (H, W) depth map as float32 ``.npy``."""
    save_npy(path, np.asarray(depth, dtype=np.float32))


def read_depth(path: Path, expected_hw: tuple[int, int] | None = None) -> np.ndarray:
    """Read an (H, W) float depth ``.npy`` (also (1, H, W) / (H, W, 1)) as float32; checks NaN / inf."""
    arr = load_npy(path)
    if arr.ndim == 3 and 1 in (arr.shape[0], arr.shape[2]):
        arr = arr.reshape(arr.shape[1:] if arr.shape[0] == 1 else arr.shape[:2])
    if arr.ndim != 2:
        raise BenchInputError(path, f"depth has shape {arr.shape}, expected (H, W)")
    if not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)):
        raise BenchInputError(path, f"depth has dtype {arr.dtype}, expected float")
    check_finite(path, arr)
    check_size(path, arr.shape, expected_hw)
    return arr.astype(np.float32)


# ---------------------------------------------------------------------------------------- normals
def encode_normal(normal: np.ndarray) -> np.ndarray:
    """(H, W, 3) unit normals (OpenCV camera frame) -> (3, H, W) float32 in [0, 1] (MonoSDF storage)."""
    return (np.transpose(np.asarray(normal, dtype=np.float32), (2, 0, 1)) * np.float32(0.5) + np.float32(0.5)).astype(
        np.float32
    )


def decode_normal(stored: np.ndarray) -> np.ndarray:
    """(3, H, W) [0, 1] -> (H, W, 3) float32 unit normals (zero vectors stay zero)."""
    n = np.transpose(stored.astype(np.float32), (1, 2, 0)) * np.float32(2.0) - np.float32(1.0)
    norm = np.linalg.norm(n, axis=-1, keepdims=True)
    return np.where(norm > 1e-6, n / np.maximum(norm, 1e-12), 0.0).astype(np.float32)


def write_mono_normal(path: Path, normal: np.ndarray) -> None:
    """Write an (H, W, 3) unit normal map as MonoSDF's (3, H, W) [0, 1] float32 ``.npy``."""
    save_npy(path, encode_normal(normal))


def read_mono_normal(path: Path, expected_hw: tuple[int, int] | None = None) -> np.ndarray:
    """Read MonoSDF's (3, H, W) [0, 1] normal ``.npy`` as (H, W, 3) float32 unit normals."""
    arr = load_npy(path)
    if arr.ndim != 3 or arr.shape[0] != 3:
        raise BenchInputError(path, f"normal has shape {arr.shape}, expected (3, H, W)")
    if not np.issubdtype(arr.dtype, np.floating):
        raise BenchInputError(path, f"normal has dtype {arr.dtype}, expected float")
    check_finite(path, arr)
    check_size(path, arr.shape[1:], expected_hw)
    return decode_normal(arr)


def write_gt_normal(path: Path, normal: np.ndarray) -> None:
    """Write an (H, W, 3) GT normal map as float32 ``.npy`` (lossless)."""
    save_npy(path, np.asarray(normal, dtype=np.float32))


def read_gt_normal(path: Path, expected_hw: tuple[int, int] | None = None) -> np.ndarray:
    """Read an (H, W, 3) float32 GT normal ``.npy``."""
    arr = load_npy(path)
    if arr.ndim != 3 or arr.shape[2] != 3:
        raise BenchInputError(path, f"normal has shape {arr.shape}, expected (H, W, 3)")
    check_finite(path, arr)
    check_size(path, arr.shape[:2], expected_hw)
    return arr.astype(np.float32)
