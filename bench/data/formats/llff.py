"""LLFF forward-facing scenes (``poses_bounds.npy`` + image folders), as NeRF / FSGS read them.

Files of the real format:

==========================  ========  =====================================================================
file                        needed?   content
==========================  ========  =====================================================================
``poses_bounds.npy``        required  (N, 17) float64: (3, 5) ``[down, right, backwards | centre | hwf]``
                                      flattened row-major, then near, far (see :mod:`bench.data.formats.cameras`)
``images/*``                factor 1  full-resolution images (.png / .jpg), sorted by name = pose order
``images_{N}/*``            factor N  the same images downsampled by N (needed only when loading with
                                      ``factor=N``)
==========================  ========  =====================================================================

Our extras (optional, always at FULL resolution): ``mono_depth/``, ``mono_normal/``, ``gt_depth/``,
``gt_normal/``, ``gt_instance/``, ``seg/`` sub-folders and ``meta.json``, ``segments.json``,
``instances.json``, ``gt_mesh.ply`` (see :mod:`bench.data.formats.extras`). ``meta.json`` also carries the
scene's ``scale_mat`` (the format has none).

Intrinsics. LLFF stores one focal length per view (``hwf``) and assumes the principal point at the
image centre. We read that as, at full resolution, ``fx = fy = focal``, ``cx = (W - 1) / 2``,
``cy = (H - 1) / 2`` in our integer-pixel-centre convention (the image centre; NeRF's ``get_rays`` uses
``W / 2`` with integer pixel coordinates, half a pixel off: a deliberate difference). The writer
therefore refuses a Scene whose K is not of this form. At ``factor`` N with images of size
``w x h``: ``sx = w / W``, ``sy = h / H``, ``fx' = fx sx``, ``cx' = (cx + 0.5) sx - 0.5`` (likewise y),
which is exact for area downsampling and keeps the principal point at the image centre.

Downsampling. The writer makes ``images_{N}`` (fmt option ``factors``, e.g. ``(2,)``; H and W must be
divisible by N) from the 8-bit image with PIL ``Image.resize(..., Image.Resampling.BOX)`` (area
average). The loader resamples the full-resolution extras to the loaded size by NEAREST sampling:
output pixel (r, c) takes source pixel ``(floor((r + 0.5) H / h), floor((c + 0.5) W / w))``, so ids,
depth edges and unit normals are never blended.

Bounds. ``near, far`` = the 0.1 and 99.9 percentiles of the view's valid GT z-depth (as LLFF's
``imgs2poses`` does with COLMAP point depths), or fmt option ``bounds=(near, far)`` without GT depth.

Without ``meta.json``: kind ``"forward"``; splits FSGS-style: ``test`` = views with index % 8 == 0,
``train`` = 3 views evenly spaced over the rest (``round(linspace(0, len(rest) - 1, 3))``); scale_mat =
a sphere around the camera frusta between the bounds (:func:`default_scale_mat`).

The loader puts the per-view ``(near, far)`` bounds in ``Scene.metadata["llff_bounds"]`` and the factor in
``metadata["llff_factor"]`` (Scene has no bounds field).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Sequence

import numpy as np
from PIL import Image

from bench.data.errors import BenchInputError
from bench.data.formats import codec, extras
from bench.data.formats.cameras import is_rotation, llff_to_opencv, opencv_to_llff
from bench.data.formats.npz import load_npy, save_npy
from bench.data.scene import Scene

POSES_FILE = "poses_bounds.npy"
_IMAGE_EXTS = {".png", ".jpg", ".jpeg"}
RESAMPLE = Image.Resampling.BOX


def image_dir(factor: int) -> str:
    """``images`` for factor 1, else ``images_{factor}``."""
    return "images" if factor == 1 else f"images_{factor}"


def centred_intrinsics(focal: float, height: int, width: int) -> np.ndarray:
    """(3, 3) K of an LLFF view at full resolution: fx = fy = focal, principal point at the image centre."""
    return np.array([[focal, 0.0, (width - 1) / 2.0], [0.0, focal, (height - 1) / 2.0], [0.0, 0.0, 1.0]])


def scale_intrinsics(K: np.ndarray, sx: float, sy: float) -> np.ndarray:
    """K (..., 3, 3) for an image resized by (sx, sy) under area resampling (integer pixel centres)."""
    out = np.array(K, dtype=np.float64, copy=True)
    out[..., 0, 0] *= sx
    out[..., 0, 1] *= sx
    out[..., 1, 1] *= sy
    out[..., 0, 2] = (out[..., 0, 2] + 0.5) * sx - 0.5
    out[..., 1, 2] = (out[..., 1, 2] + 0.5) * sy - 0.5
    return out


def resize_nearest(arr: np.ndarray, hw: tuple[int, int]) -> np.ndarray:
    """Nearest-resample (N, H, W[, C]) to (N, h, w[, C]) with source index floor((i + 0.5) * H / h)."""
    H, W = arr.shape[1:3]
    h, w = hw
    rows = np.minimum(((np.arange(h) + 0.5) * H / h).astype(np.int64), H - 1)
    cols = np.minimum(((np.arange(w) + 0.5) * W / w).astype(np.int64), W - 1)
    return arr[:, rows][:, :, cols]


def view_bounds(depth: np.ndarray) -> tuple[float, float]:
    """(near, far) = 0.1 / 99.9 percentiles of the valid (> 0) values of an (H, W) z-depth map."""
    valid = depth[depth > 0]
    if valid.size == 0:
        raise ValueError("no valid depth")
    return float(np.percentile(valid, 0.1)), float(np.percentile(valid, 99.9))


def default_scale_mat(K: np.ndarray, c2w: np.ndarray, bounds: np.ndarray, hw: tuple[int, int]) -> np.ndarray:
    """(4, 4) scale_mat whose unit sphere holds every camera centre and frustum corner at near and far.

    K: (N, 3, 3); c2w: (N, 4, 4); bounds: (N, 2) near, far; hw: image (H, W).
    """
    h, w = hw
    corners = np.array([[-0.5, -0.5, 1], [w - 0.5, -0.5, 1], [-0.5, h - 0.5, 1], [w - 0.5, h - 0.5, 1]]).T
    pts = [c2w[:, :3, 3]]
    for i in range(len(K)):
        dirs = np.linalg.inv(K[i]) @ corners  # (3, 4), z = 1
        for d in bounds[i]:
            pts.append((c2w[i, :3, :3] @ (dirs * d)).T + c2w[i, :3, 3])
    every = np.concatenate(pts)
    lo, hi = every.min(0), every.max(0)
    centre, radius = (lo + hi) / 2, max(float(np.linalg.norm(hi - lo)) / 2, 1e-6)
    S = np.diag([radius, radius, radius, 1.0])
    S[:3, 3] = centre
    return S


def default_splits(n: int, n_train: int = 3) -> dict[str, np.ndarray]:
    """FSGS splits: test = index % 8 == 0; train = n_train views evenly spaced over the rest."""
    idx = np.arange(n, dtype=np.int64)
    test, rest = idx[idx % 8 == 0], idx[idx % 8 != 0]
    if rest.size == 0:
        return {"test": test}
    pick = np.unique(np.round(np.linspace(0, rest.size - 1, min(n_train, rest.size))).astype(np.int64))
    return {"train": rest[pick], "test": test}


# ------------------------------------------------------------------------------ writer
def write(
    scene: Scene,
    out_dir: Path,
    fmt: str = "llff",
    gt_mesh: Any = None,
    factors: Sequence[int] = (),
    bounds: tuple[float, float] | None = None,
    image_name: str = "IMG_{i:04d}.png",
) -> None:
    """Write ``scene`` as LLFF (full-res ``images/``, ``images_{N}`` for N in ``factors``, poses_bounds.npy).

    Raises BenchInputError if K is not LLFF-representable, a factor does not divide H and W, or there is
    neither GT depth nor ``bounds`` to set near / far.
    """
    n, H, W = scene.num_views, scene.height, scene.width
    where = f"scene {scene.name!r} (llff)"
    for i, K in enumerate(scene.intrinsics):
        expected = centred_intrinsics(float(K[0, 0]), H, W)
        if not np.allclose(K, expected, atol=1e-6, rtol=0):
            raise BenchInputError(
                where,
                f"view {i}: LLFF needs fx == fy, no skew and principal point ((W-1)/2, (H-1)/2); got K={K.tolist()}",
            )
    factors = tuple(int(f) for f in factors)
    for f in factors:
        if f < 2 or H % f or W % f:
            raise BenchInputError(where, f"factor {f} must be >= 2 and divide the image size {W}x{H}")
    if scene.gt_depth is None and bounds is None:
        raise BenchInputError(where, "LLFF near/far bounds need GT depth or the fmt option bounds=(near, far)")

    names = [image_name.format(i=i) for i in range(n)]
    if len(set(names)) != n or sorted(names) != names:
        raise BenchInputError(where, f"image_name {image_name!r} must give distinct names sorting in view order")
    (out_dir / "images").mkdir()
    for f in factors:
        (out_dir / image_dir(f)).mkdir()
    rows = []
    for i in range(n):
        img8 = codec.quantise_rgb(scene.images[i])
        codec.write_rgb_uint8(out_dir / "images" / names[i], img8)
        for f in factors:
            small = Image.fromarray(img8, mode="RGB").resize((W // f, H // f), RESAMPLE)
            small.save(out_dir / image_dir(f) / names[i], format="PNG")
        if scene.gt_depth is not None:
            try:
                near, far = view_bounds(scene.gt_depth[i])
            except ValueError:
                raise BenchInputError(where, f"view {i} has no valid GT depth for the LLFF bounds") from None
        else:
            assert bounds is not None
            near, far = float(bounds[0]), float(bounds[1])
        mat = np.concatenate([opencv_to_llff(scene.cam_to_world[i]), [[H], [W], [scene.intrinsics[i, 0, 0]]]], axis=1)
        rows.append(np.concatenate([mat.ravel(), [near, far]]))
    save_npy(out_dir / POSES_FILE, np.asarray(rows, dtype=np.float64))
    prefixes = tuple(f"{i:06d}" for i in range(n))
    extras.write_view_maps(scene, extras.Layout(out_dir, prefixes, flat=False))
    extras.write_side_files(scene, out_dir, "llff", gt_mesh)


# ------------------------------------------------------------------------------ loader
def read_poses_bounds(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple[int, int]]:
    """Read ``poses_bounds.npy``.

    Returns:
        cam_to_world (N, 4, 4) OpenCV, focal (N,) full-res pixels, bounds (N, 2) near/far,
        full-resolution (H, W).
    """
    arr = load_npy(path)
    if arr.ndim != 2 or arr.shape[1] != 17 or arr.shape[0] == 0:
        raise BenchInputError(path, f"has shape {arr.shape}, expected (N, 17)")
    if not np.all(np.isfinite(arr)):
        raise BenchInputError(path, "contains NaN or inf")
    arr = arr.astype(np.float64)
    mats = arr[:, :15].reshape(-1, 3, 5)
    hwf = mats[:, :, 4]
    if not (np.all(hwf[:, :2] == hwf[0, :2]) and np.all(hwf[:, :2] > 0)):
        raise BenchInputError(path, "image height/width (hwf) differ between views or are not positive")
    if np.any(hwf[:, 2] <= 0):
        raise BenchInputError(path, f"focal of view {int(np.argmax(hwf[:, 2] <= 0))} is not positive")
    c2w = []
    for i, m in enumerate(mats):
        if abs(np.linalg.det(m[:, :3])) < 1e-9:
            raise BenchInputError(path, f"pose {i} is not invertible")
        if not is_rotation(m[:, :3]):
            raise BenchInputError(path, f"pose {i} rotation is not orthonormal with determinant +1")
        c2w.append(llff_to_opencv(m[:, :4]))
    bounds = arr[:, 15:17].copy()
    bad = np.flatnonzero((bounds[:, 0] <= 0) | (bounds[:, 1] <= bounds[:, 0]))
    if bad.size:
        i = int(bad[0])
        raise BenchInputError(path, f"bounds of view {i} are near {bounds[i, 0]:g}, far {bounds[i, 1]:g}: need 0 < near < far")
    H, W = int(round(hwf[0, 0])), int(round(hwf[0, 1]))
    return np.stack(c2w), hwf[:, 2].copy(), bounds, (H, W)


def load(root: Path, fmt: str = "llff", factor: int = 1) -> Scene:
    """Load an LLFF scene at ``factor`` (reads ``images_{factor}``; K and extras scaled to match)."""
    pose_path = root / POSES_FILE
    c2w, focal, bounds, (H, W) = read_poses_bounds(pose_path)
    n = c2w.shape[0]
    factor = int(factor)
    if factor < 1:
        raise BenchInputError("factor", f"must be >= 1, got {factor}")
    folder = root / image_dir(factor)
    if not folder.is_dir():
        raise BenchInputError(folder, "folder is missing")
    paths = sorted(p for p in folder.iterdir() if p.suffix.lower() in _IMAGE_EXTS)
    if len(paths) != n:
        raise BenchInputError(folder, f"holds {len(paths)} images but {pose_path.name} has {n} poses")
    first = codec.read_rgb(paths[0])
    hw = first.shape[:2]
    h, w = hw
    if factor == 1 and hw != (H, W):
        raise BenchInputError(paths[0], f"size {w}x{h} differs from {W}x{H} in {pose_path.name}")
    if abs(w - W / factor) > 1 or abs(h - H / factor) > 1:
        raise BenchInputError(paths[0], f"size {w}x{h} is not {W}x{H} / {factor}")
    images = np.stack([first] + [codec.read_rgb(p, hw) for p in paths[1:]])

    K_full = np.stack([centred_intrinsics(f, H, W) for f in focal])
    K = scale_intrinsics(K_full, w / W, h / H) if factor != 1 else K_full

    maps = extras.read_view_maps(extras.Layout(root, tuple(f"{i:06d}" for i in range(n)), flat=False), (H, W))
    if hw != (H, W):
        maps = {k: (None if v is None else resize_nearest(v, hw)) for k, v in maps.items()}

    side = extras.read_side_files(root)
    scale_mat = extras.meta_scale_mat(side.meta, root / extras.META_FILE) if side.meta else None
    if scale_mat is None:
        scale_mat = default_scale_mat(K, c2w, bounds, hw)
    return extras.build_scene(root, "llff", "forward", images, K, c2w, scale_mat, maps, side, splits=default_splits(n),
                              metadata_extra={"llff_factor": factor, "llff_bounds": bounds.tolist()})
