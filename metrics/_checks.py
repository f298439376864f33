"""Input checks shared by the metric modules (private).

Every public metric validates its inputs with these helpers *before* computing, so a wrong shape or
type fails with a message naming the argument, its shape and what was expected.
"""

from __future__ import annotations

from typing import Any

import numpy as np


def to_numpy(x: Any, name: str) -> np.ndarray:
    """numpy view of a numpy array or torch tensor (detached, on CPU); TypeError otherwise."""
    if isinstance(x, np.ndarray):
        return x
    try:
        import torch
    except ImportError:  # pragma: no cover - torch is a hard dependency of the project
        torch = None  # type: ignore[assignment]
    if torch is not None and isinstance(x, torch.Tensor):
        return x.detach().cpu().numpy()
    raise TypeError(f"{name} must be a numpy.ndarray or torch.Tensor, got {type(x).__name__}")


def as_points(x: Any, name: str, allow_empty: bool = False) -> np.ndarray:
    """Validate a point cloud and return it as a C-contiguous (N, 3) float64 array.

    Raises:
        TypeError: not an array / tensor, or not a real floating or integer dtype.
        ValueError: shape is not (N, 3), the cloud is empty (unless ``allow_empty``), or it holds NaN/inf.
    """
    a = to_numpy(x, name)
    if not (np.issubdtype(a.dtype, np.floating) or np.issubdtype(a.dtype, np.integer)):
        raise TypeError(f"{name} must have a real dtype, got {a.dtype}")
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"{name} must have shape (N, 3), got {tuple(a.shape)}")
    if a.shape[0] == 0 and not allow_empty:
        raise ValueError(f"{name} is empty (shape {tuple(a.shape)}): need at least one point")
    a = np.ascontiguousarray(a, dtype=np.float64)
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} contains NaN or inf coordinates ({int((~np.isfinite(a)).any(1).sum())} points)")
    return a


def check_positive(value: Any, name: str, allow_zero: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f"{name} must be a real number, got {type(value).__name__}")
    v = float(value)
    if not np.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        raise ValueError(f"{name} must be {'>= 0' if allow_zero else '> 0'} and finite, got {value}")
    return v


def check_int(value: Any, name: str, minimum: int = 1) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{name} must be an int, got {type(value).__name__}")
    if int(value) < minimum:
        raise ValueError(f"{name} must be >= {minimum}, got {value}")
    return int(value)


def as_cameras(
    K: Any, cam_to_world: Any, height: int, width: int
) -> tuple[np.ndarray, np.ndarray, int, int]:
    """Validate cameras: K (3, 3) or (N, 3, 3); cam_to_world (4, 4) or (N, 4, 4); H, W > 0.

    Returns (K (N, 3, 3) float64, cam_to_world (N, 4, 4) float64, H, W); a single K is broadcast to N.
    """
    c2w = to_numpy(cam_to_world, "cam_to_world")
    Km = to_numpy(K, "K")
    if c2w.ndim == 2:
        c2w = c2w[None]
    if c2w.ndim != 3 or c2w.shape[1:] != (4, 4) or c2w.shape[0] == 0:
        raise ValueError(f"cam_to_world must have shape (N, 4, 4) or (4, 4) with N >= 1, got {tuple(to_numpy(cam_to_world, 'cam_to_world').shape)}")
    n = c2w.shape[0]
    if Km.ndim == 2:
        Km = np.broadcast_to(Km, (n, *Km.shape))
    if Km.ndim != 3 or Km.shape[1:] != (3, 3) or Km.shape[0] != n:
        raise ValueError(f"K must have shape (3, 3) or ({n}, 3, 3) to match cam_to_world, got {tuple(to_numpy(K, 'K').shape)}")
    c2w = np.asarray(c2w, dtype=np.float64)
    Km = np.asarray(Km, dtype=np.float64)
    if not (np.all(np.isfinite(c2w)) and np.all(np.isfinite(Km))):
        raise ValueError("K and cam_to_world must be finite")
    h = check_int(height, "H")
    w = check_int(width, "W")
    return Km, c2w, h, w
