"""Camera conversions: IDR/MonoSDF world_mat decomposition and LLFF <-> OpenCV."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from bench.data.errors import BenchInputError
from bench.data.formats.cameras import (
    compose_world_mat,
    decompose_projection,
    decompose_world_mat,
    llff_to_opencv,
    opencv_to_llff,
)

RNG = np.random.default_rng(7)


def random_pose() -> np.ndarray:
    c2w = np.eye(4)
    c2w[:3, :3] = Rotation.random(random_state=RNG.integers(1 << 31)).as_matrix()
    c2w[:3, 3] = RNG.normal(size=3) * 3
    return c2w


def test_llff_to_opencv_matches_nerf_reordering():
    """NeRF load_llff: OpenGL [right, up, back] = [c1, -c0, c2]; OpenCV = OpenGL with y, z negated."""
    for _ in range(10):
        c2w = random_pose()
        llff = opencv_to_llff(c2w)
        gl = np.concatenate([llff[:, 1:2], -llff[:, 0:1], llff[:, 2:]], axis=1)
        cv = gl[:, :3] @ np.diag([1.0, -1.0, -1.0])
        np.testing.assert_array_equal(cv, c2w[:3, :3])
        np.testing.assert_array_equal(gl[:, 3], c2w[:3, 3])
        # both directions are exact (a permutation and sign flips)
        np.testing.assert_array_equal(llff_to_opencv(llff), c2w)
        np.testing.assert_array_equal(opencv_to_llff(llff_to_opencv(llff)), llff)


def test_llff_axes_meaning():
    """A camera at the origin looking along world -z with image-up = world +y (the OpenGL identity)."""
    c2w_cv = np.diag([1.0, -1.0, -1.0, 1.0])
    llff = opencv_to_llff(c2w_cv)
    np.testing.assert_array_equal(llff[:, 0], [0, -1, 0])  # down
    np.testing.assert_array_equal(llff[:, 1], [1, 0, 0])  # right
    np.testing.assert_array_equal(llff[:, 2], [0, 0, 1])  # backwards


@pytest.mark.parametrize("with_rotation", [False, True])
def test_world_mat_roundtrip_through_scale_mat(with_rotation):
    K = np.array([[500.0, 0.3, 319.5], [0.0, 480.0, 239.5], [0.0, 0.0, 1.0]])
    S = np.eye(4)
    S[:3, :3] = 3.7 * (Rotation.from_euler("xyz", [0.2, -0.4, 1.1]).as_matrix() if with_rotation else np.eye(3))
    S[:3, 3] = [1.0, -2.0, 0.5]
    for _ in range(10):
        c2w = random_pose()
        wm = compose_world_mat(K, c2w)
        K2, c2w2 = decompose_world_mat(wm, S, "cameras.npz", 0)
        np.testing.assert_allclose(K2, K, atol=1e-9)
        np.testing.assert_allclose(c2w2, c2w, atol=1e-9)
        # MonoSDF's own pose (camera -> normalised frame) is S^-1 applied to ours
        _, pose_n = decompose_projection((wm @ S)[:3])
        np.testing.assert_allclose(pose_n[:3, 3], (np.linalg.inv(S) @ c2w[:, 3])[:3], atol=1e-9)
        # a projection matrix is defined up to scale, also a negative one
        K3, c2w3 = decompose_world_mat(-2.0 * wm, S, "cameras.npz", 0)
        np.testing.assert_allclose(K3, K, atol=1e-9)
        np.testing.assert_allclose(c2w3, c2w, atol=1e-9)


def test_world_mat_errors():
    wm = compose_world_mat(np.diag([100.0, 100.0, 1.0]), np.eye(4))
    singular = wm.copy()
    singular[2, :3] = 0
    with pytest.raises(BenchInputError, match=r"cams.npz: world_mat_3 is not invertible"):
        decompose_world_mat(singular, np.eye(4), "cams.npz", 3)
    with pytest.raises(BenchInputError, match=r"scale_mat_1 is not a similarity"):
        decompose_world_mat(wm, np.diag([1.0, 2.0, 1.0, 1.0]), "cams.npz", 1)
    with pytest.raises(BenchInputError, match=r"world_mat_2 has shape \(3, 3\)"):
        decompose_world_mat(np.eye(3), np.eye(4), "cams.npz", 2)
    bad = wm.copy()
    bad[0, 0] = np.nan
    with pytest.raises(BenchInputError, match=r"world_mat_0 contains NaN"):
        decompose_world_mat(bad, np.eye(4), "cams.npz", 0)
