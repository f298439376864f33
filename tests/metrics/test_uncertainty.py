import numpy as np
import pytest

from metrics.uncertainty import ause, region_masks, sparsification_curve, spearman, uncertainty_metrics


def test_perfect_uncertainty_has_zero_ause_and_rho_one():
    rng = np.random.default_rng(0)
    e = rng.random(1000)
    assert ause(e, e) == 0.0
    assert ause(np.exp(3 * e), e) == 0.0  # any increasing function
    assert spearman(e ** 2, e) == pytest.approx(1.0)
    assert ause(-e, e) > ause(rng.random(1000), e) > 0  # anti-correlated is worst


def test_curve_hand_example_and_ties():
    e = np.array([4.0, 3.0, 2.0, 1.0])
    fr, c = sparsification_curve(e, e, n_bins=4)
    np.testing.assert_allclose(fr, [0, 0.25, 0.5, 0.75])
    np.testing.assert_allclose(c, [2.5, 2.0, 1.5, 1.0])
    # all-equal U: tie-aware -> flat at the mean error, independent of order
    _, flat = sparsification_curve(np.ones(4), e, n_bins=4)
    np.testing.assert_allclose(flat, 2.5)
    assert ause(np.ones(4), e, n_bins=4) == pytest.approx(np.trapezoid([0, 0.5, 1.0, 1.5], [0, 0.25, 0.5, 0.75]))
    assert ause(np.ones(4), e[::-1], n_bins=4) == ause(np.ones(4), e, n_bins=4)
    assert np.isnan(spearman(np.ones(4), e))


def test_normalize_and_validation():
    rng = np.random.default_rng(1)
    e = rng.random(500)
    u = rng.random(500)
    assert ause(u, 10 * e, normalize=True) == pytest.approx(ause(u, e, normalize=True))
    assert ause(u, 10 * e) == pytest.approx(10 * ause(u, e))
    with pytest.raises(ValueError):
        ause(u, e[:10])
    with pytest.raises(ValueError):
        ause(np.array([np.nan, 1.0]), np.array([1.0, 1.0]))


def test_region_masks():
    inst = np.zeros((20, 20), np.int32)
    inst[:, :] = 1  # wall (background), fills the image -> never thin
    inst[5:15, 5:15] = 2  # big box: not thin
    inst[2:18, 17] = 3  # 1-pixel pole: thin
    r = region_masks(inst, background_ids=[1], kernel=3)
    assert r["thin"][2:18, 17].all() and not r["thin"][inst == 2].any() and r["thin"].sum() == 16
    assert (r["planar"] == (inst == 1)).all()
    r3 = region_masks(np.stack([inst, inst]), [1], 3)
    assert r3["thin"].shape == (2, 20, 20)
    with pytest.raises(TypeError):
        region_masks(inst.astype(float), [1])
    with pytest.raises(ValueError):
        region_masks(inst, [1], kernel=4)


def test_uncertainty_metrics_by_region():
    rng = np.random.default_rng(2)
    gt = rng.uniform(1, 3, (2, 10, 12))
    err = rng.random(gt.shape) * 0.1
    prior = gt + err
    regions = {"left": np.zeros(gt.shape, bool)}
    regions["left"][..., :6] = True
    regions["none"] = np.zeros(gt.shape, bool)
    out = uncertainty_metrics(err, prior, gt, regions=regions)
    assert out["all"].ause == pytest.approx(0, abs=1e-12) and out["all"].spearman == pytest.approx(1)
    assert out["left"].n_pixels == 120 and np.isnan(out["none"].ause)
    const = uncertainty_metrics(np.full(gt.shape, 0.5), prior, gt)["all"]
    assert const.ause > 0 and np.isnan(const.spearman)
