"""scripts/prior_bias_by_object.py: the two alignments of a depth prior to GT, on synthetic depth maps."""

from __future__ import annotations

import numpy as np


def test_an_exact_affine_prior_is_unbiased_under_both_alignments(load_script):
    gt = np.linspace(1.0, 5.0, 400).reshape(20, 20)
    gt[0, 0] = 0.0  # invalid pixel
    ratios = load_script("prior_bias_by_object").aligned_ratios(0.5 * gt + 0.3 * (gt > 0), gt)
    for r in ratios.values():
        assert np.isnan(r[0, 0])
        np.testing.assert_allclose(r[gt > 0], 1.0, atol=1e-9)


def test_prior_noise_compresses_the_prior_to_gt_fit_only(load_script):
    rng = np.random.default_rng(0)
    gt = rng.uniform(1.0, 5.0, (200, 200))
    prior = 2.0 * gt + rng.normal(0.0, 1.0, gt.shape)  # errors in the prior, independent of depth
    prior = np.clip(prior, 1e-3, None)
    r = load_script("prior_bias_by_object").aligned_ratios(prior, gt)
    far, near = gt > 4.5, gt < 1.5
    # least squares GT ~ a prior + b attenuates a: far surfaces come out closer, near ones farther
    assert np.median(r["prior_to_gt"][far]) < 0.97 and np.median(r["prior_to_gt"][near]) > 1.05
    # with GT as the regressor there is no attenuation
    assert abs(np.median(r["gt_to_prior_inverted"][far]) - 1.0) < 0.02
    assert abs(np.median(r["gt_to_prior_inverted"][near]) - 1.0) < 0.05


def test_facing_angle_of_a_fronto_parallel_and_a_tilted_plane(load_script):
    K = np.array([[50.0, 0.0, 10.0], [0.0, 50.0, 10.0], [0.0, 0.0, 1.0]])
    facing = np.zeros((21, 21, 3))
    facing[..., 2] = -1.0  # normal towards the camera (OpenCV: z forward)
    a = load_script("prior_bias_by_object").facing_angle_deg(facing, K)
    assert a[10, 10] == 0.0  # the principal point looks straight at it
    assert 0.0 < a[0, 0] < 20.0  # off-axis pixels see it at the ray's angle (atan(sqrt(2) 10 / 50) = 15.8 deg)
    np.testing.assert_allclose(a[0, 0], np.degrees(np.arctan(np.sqrt(2.0) * 10.0 / 50.0)), atol=1e-9)
    up = np.zeros((21, 21, 3))
    up[..., 1] = -1.0  # a floor's normal (y down in OpenCV): seen edge-on from the principal point
    np.testing.assert_allclose(load_script("prior_bias_by_object").facing_angle_deg(up, K)[10, 10], 90.0, atol=1e-9)
