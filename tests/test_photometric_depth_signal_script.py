"""scripts/photometric_depth_signal.py on two cameras looking at a plane with a known texture."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

H, W, F, Z, BASELINE = 48, 64, 60.0, 3.0, 0.3  # pixels, pixels, focal px, plane depth m, camera b's offset along x m


def _plane_scene(albedo) -> SimpleNamespace:
    """Camera a at the origin, camera b 0.3 m to its right, both looking down +z at the plane z = 3 m whose
    colour at world x is ``albedo(x)`` (grey)."""
    K = np.array([[F, 0.0, (W - 1) / 2], [0.0, F, (H - 1) / 2], [0.0, 0.0, 1.0]])
    poses = np.repeat(np.eye(4)[None], 2, axis=0)
    poses[1, 0, 3] = BASELINE
    u = np.arange(W, dtype=np.float64)[None, :].repeat(H, axis=0)
    images = []
    for pose in poses:
        x_world = (u - K[0, 2]) / F * Z + pose[0, 3]
        images.append(np.repeat(albedo(x_world)[..., None], 3, axis=-1))
    return SimpleNamespace(height=H, width=W, intrinsics=np.stack([K, K]), cam_to_world=poses, images=np.stack(images),
                           gt_depth=np.full((2, H, W), Z), gt_instance=np.ones((2, H, W), dtype=np.int32))


def test_a_textured_plane_is_consistent_at_its_depth_and_not_3_percent_further(load_script):
    scene = _plane_scene(lambda x: 0.5 + 0.4 * np.sin(2 * np.pi * x / 0.5))  # 0.5 m period: 10 px per period at 3 m
    ids, res = load_script("photometric_depth_signal").pair_residuals(scene, 0, 1, [1.0, 1.03])
    assert len(ids) > 0.5 * H * W  # the part of view a that view b sees (b is 0.3 m to the right: 6 px of 64 lost)
    at_gt, pushed = np.nanmean(res[1.0]), np.nanmean(res[1.03])
    # x 1.00: only bilinear resampling error of the sinusoid (< 0.005); x 1.03: the point lands 0.175 px off in
    # view b (F (0.3 - 0.3 / 1.03) / Z), 8.7 mm on the plane: mean |d colour| ~ 0.4 * 2 pi / 0.5 * 0.0087 * 2 / pi = 0.028
    assert at_gt < 0.005
    assert 0.02 < pushed < 0.035


def test_a_plain_plane_carries_no_depth_signal(load_script):
    scene = _plane_scene(lambda x: np.full_like(x, 0.6))
    _, res = load_script("photometric_depth_signal").pair_residuals(scene, 0, 1, [1.0, 1.03])
    np.testing.assert_allclose(np.nan_to_num(res[1.0]), 0.0, atol=1e-12)
    np.testing.assert_allclose(np.nan_to_num(res[1.03]), 0.0, atol=1e-12)
