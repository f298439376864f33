import numpy as np
import pytest

from metrics.depth import align_depth, depth_metrics


def scene(seed=0):
    rng = np.random.default_rng(seed)
    gt = rng.uniform(1.0, 4.0, (2, 20, 30))
    gt[:, 0, :] = 0  # invalid row
    return gt


def test_perfect_and_known_values():
    gt = scene()
    m = depth_metrics(gt, gt)
    assert m.abs_rel == 0 and m.rmse == 0 and m.delta1 == 1
    m = depth_metrics(gt * 1.1, gt)
    assert m.abs_rel == pytest.approx(0.1) and m.delta1 == 1
    v = gt > 0
    assert m.rmse == pytest.approx(np.mean([np.sqrt(np.mean((0.1 * gt[i][v[i]]) ** 2)) for i in range(2)]))
    assert depth_metrics(gt * 1.3, gt).delta1 == 0


@pytest.mark.parametrize("mode", ["scale", "scale_shift"])
def test_alignment_recovers_affine_prior(mode):
    gt = scene(1)
    prior = (gt - (0.5 if mode == "scale_shift" else 0)) / 3.0
    prior[gt == 0] = 7.0
    m = depth_metrics(prior, gt, align=mode)
    assert m.abs_rel == pytest.approx(0, abs=1e-9) and m.delta1 == 1
    s, t = align_depth(prior[0], gt[0], mode=mode)
    assert s == pytest.approx(3.0) and t == pytest.approx(0.5 if mode == "scale_shift" else 0.0)
    # per image: a different scale per image is still recovered
    prior2 = prior.copy()
    prior2[1] *= 5
    assert depth_metrics(prior2, gt, align=mode).abs_rel == pytest.approx(0, abs=1e-9)


def test_errors_and_singular():
    gt = scene()
    with pytest.raises(ValueError, match="singular"):
        depth_metrics(np.ones_like(gt), gt, align="scale_shift")
    with pytest.raises(ValueError, match="differ"):
        depth_metrics(gt[0], gt)
    with pytest.raises(ValueError, match="no valid"):
        depth_metrics(gt, np.zeros_like(gt))
    with pytest.raises(ValueError, match="align"):
        depth_metrics(gt, gt, align="median")
    with pytest.raises(TypeError):
        depth_metrics(gt, gt, mask=np.ones_like(gt))


def test_mask_restricts():
    gt = scene()
    pred = gt.copy()
    pred[:, 10:] *= 2
    mask = np.zeros(gt.shape, bool)
    mask[:, :10] = True
    assert depth_metrics(pred, gt, mask=mask).abs_rel == 0
