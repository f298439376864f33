"""metrics.camera: the one pinhole module (pixel rays, back-projection, projection) every layer uses."""

from __future__ import annotations

import numpy as np

from metrics.camera import backproject, backproject_pixels, pixel_rays, pixels_to_rays, project, to_world


def _camera(seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    K = np.array([[60.0, 0.0, 31.7], [0.0, 58.0, 24.2], [0.0, 0.0, 1.0]])
    a, b = rng.uniform(-0.5, 0.5, 2)
    Rx = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    Ry = np.array([[np.cos(b), 0, np.sin(b)], [0, 1, 0], [-np.sin(b), 0, np.cos(b)]])
    c2w = np.eye(4)
    c2w[:3, :3], c2w[:3, 3] = Rx @ Ry, rng.normal(size=3)
    return K, c2w


def test_rays_have_unit_z_and_hit_their_pixel() -> None:
    K, _ = _camera()
    rays = pixel_rays(K, 48, 64)
    assert rays.shape == (48, 64, 3) and np.all(rays[..., 2] == 1.0)
    pix = rays @ K.T  # back to homogeneous pixels
    v, u = np.mgrid[0:48, 0:64]
    np.testing.assert_allclose(pix[..., 0], u, atol=1e-9)
    np.testing.assert_allclose(pix[..., 1], v, atol=1e-9)
    np.testing.assert_array_equal(pixels_to_rays(K, np.array([3.0]), np.array([5.0]))[0], rays[5, 3])


def test_backproject_then_project_is_the_identity() -> None:
    K, c2w = _camera(1)
    depth = np.random.default_rng(2).uniform(0.5, 4.0, (48, 64))
    world = backproject(depth, K, c2w)
    u, v, z = project(world.reshape(-1, 3), K, c2w)
    vv, uu = np.mgrid[0:48, 0:64]
    np.testing.assert_allclose(u, uu.ravel(), atol=1e-8)
    np.testing.assert_allclose(v, vv.ravel(), atol=1e-8)
    np.testing.assert_allclose(z, depth.ravel(), rtol=1e-12)
    rows, cols = np.array([0, 7, 47]), np.array([63, 2, 0])
    np.testing.assert_array_equal(backproject_pixels(depth, rows, cols, K, c2w), world[rows, cols])
    centre = backproject(np.zeros((2, 2)), K, c2w)  # invalid depth: the camera centre
    np.testing.assert_allclose(centre, np.broadcast_to(c2w[:3, 3], (2, 2, 3)))


def test_points_behind_the_camera_have_no_pixel() -> None:
    K, c2w = _camera(3)
    behind = to_world(np.array([[0.1, 0.2, -1.0], [0.0, 0.0, 0.0]]), c2w)
    u, v, z = project(behind, K, c2w)
    assert np.all(np.isnan(u)) and np.all(np.isnan(v)) and z[0] < 0 and abs(z[1]) < 1e-12
