"""scripts/initial_sphere_placement.py (and the ray-sphere exit it shares with the trainer's build_rays) on a camera
looking at a plane at a known depth."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

H, W, F = 24, 32, 30.0  # pixels, pixels, focal length in pixels


def _camera_before_a_plane(depth_m: float, camera_at: np.ndarray) -> SimpleNamespace:
    """One camera at ``camera_at`` (world, metres) looking down +z at the plane z = camera z + ``depth_m``."""
    K = np.array([[F, 0.0, (W - 1) / 2], [0.0, F, (H - 1) / 2], [0.0, 0.0, 1.0]])
    pose = np.eye(4)
    pose[:3, 3] = camera_at
    return SimpleNamespace(height=H, width=W, intrinsics=K[None], cam_to_world=pose[None],
                           gt_depth=np.full((1, H, W), depth_m))


def test_sphere_exit_distance_from_the_centre_is_the_radius_and_off_centre_solves_the_quadratic():
    from methods.monosdf.rays import sphere_exit_distance

    dirs = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 0.6, 0.8]])
    np.testing.assert_allclose(sphere_exit_distance(np.zeros(3), dirs, 2.5), 2.5)
    # from (1, 0, 0) along +x the sphere of radius 3 is 2 away, along -x 4, along +y sqrt(9 - 1)
    o = np.array([1.0, 0.0, 0.0])
    d = np.array([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    np.testing.assert_allclose(sphere_exit_distance(o, d, 3.0), [2.0, 4.0, np.sqrt(8.0)])


def test_a_sphere_beyond_the_plane_is_behind_it_by_the_distance_along_each_ray(load_script):
    script = load_script("initial_sphere_placement")
    scene = _camera_before_a_plane(2.0, np.zeros(3))
    # unit 1.5 m, radius 2 units: the sphere is 3 m from the camera along every ray; the plane 2 m / cos(angle)
    excess, outside = script.sphere_minus_surface(scene, np.zeros(3), 1.5, 2.0)
    assert outside == 0 and excess.shape == (H * W,)
    v, u = np.mgrid[0:H, 0:W]
    along = 2.0 * np.sqrt(1 + ((u - (W - 1) / 2) / F) ** 2 + ((v - (H - 1) / 2) / F) ** 2)
    np.testing.assert_allclose(excess, 3.0 - along.reshape(-1), atol=1e-12)
    assert (excess > 0).all() and np.isclose(excess.max(), 1.0, atol=5e-3)  # ~1 m behind on the central rays


def test_a_sphere_short_of_the_plane_is_in_front_and_a_camera_outside_it_is_left_out(load_script):
    script = load_script("initial_sphere_placement")
    excess, outside = script.sphere_minus_surface(_camera_before_a_plane(4.0, np.zeros(3)), np.zeros(3), 1.0, 3.0)
    assert outside == 0 and (excess < 0).all() and np.isclose(excess.max(), -1.0, atol=5e-3)
    excess, outside = script.sphere_minus_surface(_camera_before_a_plane(4.0, np.array([0.0, 0.0, 3.5])), np.zeros(3), 1.0, 3.0)
    assert outside == 1 and excess.size == 0


def test_the_area_beyond_a_sphere_of_a_fine_square_is_one_minus_the_disc(load_script):
    """A 4 x 4 m square (fine triangles) about the centre, a sphere of 1 m: pi / 16 of it lies inside."""
    import trimesh

    script = load_script("initial_sphere_placement")
    plane = trimesh.creation.box(extents=[4.0, 4.0, 1e-3]).subdivide_to_size(0.02)
    top = plane.submesh([np.flatnonzero(plane.face_normals[:, 2] > 0.5)], append=True)
    assert np.isclose(script.area_beyond(top, np.zeros(3), 1.0), 1 - np.pi / 16, atol=0.01)
    assert script.area_beyond(top, np.zeros(3), 3.0) == 0.0 and script.area_beyond(top, np.zeros(3), 0.0) == 1.0
