import numpy as np
import pytest
import torch

from metrics.nn import nearest_neighbor, nearest_neighbor_bruteforce


@pytest.mark.parametrize("backend", ["scipy", "open3d"])
def test_fast_matches_bruteforce(backend):
    rng = np.random.default_rng(1)
    q, r = rng.normal(size=(700, 3)), rng.normal(size=(900, 3))
    d, i = nearest_neighbor(q, r, backend=backend)
    db, ib = nearest_neighbor_bruteforce(q, r)
    np.testing.assert_allclose(d, db, atol=1e-6, rtol=0)
    assert (i == ib).mean() > 0.999  # ties are measure-zero for random data


def test_bruteforce_is_correct_on_hand_case():
    d, i = nearest_neighbor_bruteforce(np.array([[0.0, 0, 0], [5, 0, 0]]), np.array([[1.0, 0, 0], [0, 3, 0], [4, 0, 1]]))
    np.testing.assert_allclose(d, [1.0, np.sqrt(2)])
    assert i.tolist() == [0, 2]


def test_torch_and_float32_inputs():
    rng = np.random.default_rng(2)
    q, r = rng.random((50, 3)), rng.random((60, 3))
    d64, _ = nearest_neighbor(q, r)
    d32, _ = nearest_neighbor(torch.from_numpy(q.astype(np.float32)), r.astype(np.float32))
    np.testing.assert_allclose(d32, d64, atol=1e-6)


@pytest.mark.parametrize(
    "q, err",
    [
        (np.zeros((0, 3)), ValueError),
        (np.zeros((4, 2)), ValueError),
        (np.array([[np.nan, 0, 0]]), ValueError),
        ([[0.0, 0, 0]], TypeError),
    ],
)
def test_bad_inputs(q, err):
    with pytest.raises(err):
        nearest_neighbor(q, np.zeros((3, 3)))


def test_bad_backend():
    with pytest.raises(ValueError, match="backend"):
        nearest_neighbor(np.zeros((1, 3)), np.zeros((1, 3)), backend="faiss")


def test_morton_order_is_a_permutation_that_groups_nearby_points():
    from metrics.nn import morton_order

    rng = np.random.default_rng(0)
    p = rng.uniform(-2.0, 3.0, (5000, 3))
    o = morton_order(p)
    assert o.dtype == np.int64 and np.array_equal(np.sort(o), np.arange(5000))
    # consecutive points along the curve are much closer than consecutive points in input order
    step_curve = np.linalg.norm(np.diff(p[o], axis=0), axis=1).mean()
    step_input = np.linalg.norm(np.diff(p, axis=0), axis=1).mean()
    assert step_curve < 0.25 * step_input
    assert np.array_equal(morton_order(np.ones((4, 3))), np.arange(4))  # degenerate cloud: identity


@pytest.mark.parametrize("backend", ["open3d", "scipy"])
def test_kdtree_results_come_back_in_the_callers_order(backend):
    """The KD-tree backends query in Z-order; distances and indices are mapped back to the input order
    (compared with the brute-force twin on a floater-rich cloud, the case the ordering speeds up)."""
    rng = np.random.default_rng(3)
    ref = rng.normal(size=(1500, 3)) * [1.0, 1.0, 0.02]  # a noisy plane
    q = np.concatenate([ref[:700] + rng.normal(scale=0.01, size=(700, 3)), rng.uniform(-3, 3, (800, 3))])
    q = q[rng.permutation(q.shape[0])]
    d, i = nearest_neighbor(q, ref, backend=backend)
    db, ib = nearest_neighbor_bruteforce(q, ref)
    np.testing.assert_allclose(d, db, rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(q - ref[i], axis=1), db, rtol=0, atol=1e-12)


@pytest.mark.parametrize("backend", ["open3d", "scipy"])
def test_prepared_index_matches_one_shot_queries(backend):
    from metrics.mesh import point_metrics
    from metrics.nn import NearestNeighborIndex

    rng = np.random.default_rng(5)
    gt, pred = rng.normal(size=(3000, 3)), rng.normal(size=(2000, 3)) * 1.1
    gn, pn = rng.normal(size=(3000, 3)), rng.normal(size=(2000, 3))
    index = NearestNeighborIndex(gt, backend)
    d, i = index.query(pred)
    db, ib = nearest_neighbor_bruteforce(pred, gt)
    np.testing.assert_allclose(d, db, rtol=0, atol=1e-12)
    d2, _ = NearestNeighborIndex(pred, backend).query_from(index)
    np.testing.assert_allclose(d2, nearest_neighbor_bruteforce(gt, pred)[0], rtol=0, atol=1e-12)
    once = point_metrics(pred, gt, 0.3, pn, gn, backend=backend).as_dict()
    assert point_metrics(pred, gt, 0.3, pn, gn, backend=backend, gt_index=index).as_dict() == pytest.approx(once, rel=1e-12)
    with pytest.raises(ValueError, match="gt_index holds"):
        point_metrics(pred, gt[:10], 0.3, backend=backend, gt_index=index)
