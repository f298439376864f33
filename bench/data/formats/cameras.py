"""Camera matrix conversions between the on-disk conventions and :class:`bench.data.scene.Scene`'s.

Scene convention: ``cam_to_world`` (4, 4) float64, OpenCV axes (x right, y down, z forward), world
metres; K (3, 3) in pixels with integer pixel centres.

IDR / NeuS / MonoSDF (``cameras.npz``):
    ``world_mat_i`` (4, 4) = K4 @ world_to_cam, K4 = K padded to 4x4 with a 1 at [3, 3];
    ``scale_mat_i`` (4, 4) maps the normalised unit-sphere frame to world (``x_w = S @ x_n``).
    MonoSDF decomposes ``P = (world_mat @ scale_mat)[:3, :4]`` (OpenCV ``decomposeProjectionMatrix``,
    K divided by K[2, 2]) into K and the camera-to-*normalised* pose. :func:`decompose_world_mat` does
    exactly that decomposition (an RQ decomposition with a positive-diagonal K, in float64, without
    OpenCV) and then maps the pose back to world metres through ``scale_mat``.

LLFF (``poses_bounds.npy``, (N, 17) float64): each row is a (3, 5) matrix flattened row-major
    ``[c0 c1 c2 | t | hwf]`` then ``near, far``. ``c0, c1, c2`` are camera-to-world rotation columns for
    the camera axes [down, right, backwards], ``t`` the camera centre, ``hwf = (H, W, focal)`` at full
    resolution. NeRF's ``load_llff.py`` reorders to OpenGL [right, up, backwards] = ``[c1, -c0, c2]``;
    OpenCV [right, down, forward] is therefore ``[c1, c0, -c2]`` (:func:`llff_to_opencv`). The map is a
    column permutation and a sign flip, so it is exact in both directions.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

import numpy as np

from bench.data.errors import BenchInputError


# ------------------------------------------------------------------------------ projection matrices
def compose_world_mat(K: np.ndarray, cam_to_world: np.ndarray) -> np.ndarray:
    """IDR ``world_mat`` = K4 @ world_to_cam. K: (3, 3) pixels; cam_to_world: (4, 4). Returns (4, 4) float64."""
    K4 = np.eye(4)
    K4[:3, :3] = K
    return K4 @ np.linalg.inv(np.asarray(cam_to_world, dtype=np.float64))


def _rq3(M: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """RQ decomposition M = K @ R of a (3, 3) matrix, K upper triangular with positive diagonal, R orthogonal."""
    flip = np.eye(3)[::-1]
    Q, U = np.linalg.qr((flip @ M).T)
    K = flip @ U.T @ flip
    R = flip @ Q.T
    signs = np.sign(np.diag(K))
    signs[signs == 0] = 1.0
    D = np.diag(signs)
    return K @ D, D @ R


def decompose_projection(P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Split a (3, 4) projection ``P ~ K [R | t]`` into K (3, 3), K[2, 2] = 1, and cam_to_world (4, 4).

    Equivalent to IDR / MonoSDF ``load_K_Rt_from_P`` (which calls ``cv2.decomposeProjectionMatrix``):
    K with positive diagonal, R a proper rotation (``P`` is flipped in sign if needed, a projective
    no-op), camera centre = null vector of P. Caller checks invertibility first.
    """
    M = P[:, :3]
    K, R = _rq3(M)
    if np.linalg.det(R) < 0:  # P and -P are the same camera
        K, R = _rq3(-M)
    centre = -np.linalg.solve(M, P[:, 3])
    pose = np.eye(4)
    pose[:3, :3] = R.T
    pose[:3, 3] = centre
    return K / K[2, 2], pose


def similarity_parts(S: np.ndarray) -> tuple[float, np.ndarray] | None:
    """For a similarity ``S = [s Q | t; 0 0 0 1]`` (s > 0, Q a rotation) return (s, Q); else None."""
    if not np.allclose(S[3], [0.0, 0.0, 0.0, 1.0], atol=1e-9):
        return None
    A = S[:3, :3]
    det = np.linalg.det(A)
    if not np.isfinite(det) or det <= 0:
        return None
    s = float(np.cbrt(det))
    Q = A / s
    if not np.allclose(Q.T @ Q, np.eye(3), atol=1e-6):
        return None
    return s, Q


def decompose_world_mat(
    world_mat: np.ndarray, scale_mat: np.ndarray, where: Path, index: int
) -> tuple[np.ndarray, np.ndarray]:
    """MonoSDF's decomposition of ``world_mat_i`` with ``scale_mat_i``, returned in world metres.

    Args:
        world_mat: (4, 4) (or (3, 4)) K4 @ world_to_cam.
        scale_mat: (4, 4) similarity, normalised -> world.
        where: the cameras file (for error messages); index: the view index i.

    Returns:
        K (3, 3) float64 pixels; cam_to_world (4, 4) float64, OpenCV axes, world metres.

    Raises:
        BenchInputError naming ``where`` and ``world_mat_i`` / ``scale_mat_i`` if a matrix has the wrong
        shape, is not finite, is not invertible or (scale_mat) is not a similarity.
    """
    wm = np.asarray(world_mat, dtype=np.float64)
    sm = np.asarray(scale_mat, dtype=np.float64)
    if wm.shape not in ((4, 4), (3, 4)):
        raise BenchInputError(where, f"world_mat_{index} has shape {wm.shape}, expected (4, 4)")
    if sm.shape != (4, 4):
        raise BenchInputError(where, f"scale_mat_{index} has shape {sm.shape}, expected (4, 4)")
    if not np.all(np.isfinite(wm)):
        raise BenchInputError(where, f"world_mat_{index} contains NaN or inf")
    if not np.all(np.isfinite(sm)):
        raise BenchInputError(where, f"scale_mat_{index} contains NaN or inf")
    if wm.shape == (3, 4):
        wm = np.vstack([wm, [0.0, 0.0, 0.0, 1.0]])
    if np.linalg.cond(wm[:3, :3]) > 1e12:
        raise BenchInputError(where, f"world_mat_{index} is not invertible")
    parts = similarity_parts(sm)
    if parts is None:
        raise BenchInputError(where, f"scale_mat_{index} is not a similarity (uniform scale, rotation, translation)")
    _, Q = parts
    P = (wm @ sm)[:3, :4]  # MonoSDF: P = world_mat @ scale_mat
    K, pose_normalised = decompose_projection(P)  # camera -> normalised frame
    cam_to_world = np.eye(4)
    cam_to_world[:3, :3] = Q @ pose_normalised[:3, :3]
    cam_to_world[:3, 3] = sm[:3, :3] @ pose_normalised[:3, 3] + sm[:3, 3]
    return K, cam_to_world


# ------------------------------------------------------------------------------ LLFF
def opencv_to_llff(cam_to_world: np.ndarray) -> np.ndarray:
    """(4, 4) OpenCV camera-to-world -> (3, 4) LLFF ``[down, right, backwards | centre]``."""
    R, t = cam_to_world[:3, :3], cam_to_world[:3, 3]
    return np.stack([R[:, 1], R[:, 0], -R[:, 2], t], axis=1)


def llff_to_opencv(mat34: np.ndarray) -> np.ndarray:
    """(3, 4) LLFF ``[down, right, backwards | centre]`` -> (4, 4) OpenCV camera-to-world."""
    out = np.eye(4)
    out[:3, 0] = mat34[:, 1]
    out[:3, 1] = mat34[:, 0]
    out[:3, 2] = -mat34[:, 2]
    out[:3, 3] = mat34[:, 3]
    return out


def is_rotation(R: np.ndarray, atol: float = 1e-4) -> bool:
    """True if R (3, 3) is orthonormal with determinant +1 (within ``atol``)."""
    if not np.all(np.isfinite(R)):
        return False
    return bool(np.allclose(R.T @ R, np.eye(3), atol=atol) and abs(np.linalg.det(R) - 1) < atol)


def check_view_numbering(paths: list[Path], index_of: Callable[[Path], str], cameras: str) -> None:
    """Formats that pair the i-th image (sorted by name) with camera i (IDR / MonoSDF ``world_mat_i``)
    silently give every image after a gap its neighbour's pose. When the names are numbers they must be
    consecutive (they may start anywhere: real MonoSDF folders do); a view missing at either end shows
    as more cameras than images instead. ``index_of`` maps a path to its number's text; ``cameras`` names
    the camera file."""
    stems = [index_of(p) for p in paths]
    if not stems or not all(s.isdigit() for s in stems):
        return
    first = int(stems[0])
    for i, (p, s) in enumerate(zip(paths, stems)):
        if int(s) != first + i:
            raise BenchInputError(p.parent, f"image number {first + i} is missing (the next is {p.name}); images are "
                                  f"paired with {cameras} by position, so the numbers must be consecutive")
