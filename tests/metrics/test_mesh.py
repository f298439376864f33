import numpy as np
import pytest
import trimesh

from metrics.mesh import MeshMetrics, clean_mesh, evaluate_mesh_pair, point_metrics, sample_mesh_surface


def sphere(r):
    m = trimesh.creation.icosphere(subdivisions=5, radius=1.0)
    return trimesh.Trimesh(m.vertices * r, m.faces, process=False)


def test_concentric_spheres_closed_form():
    # Every point of a sphere of radius a is at distance |a - b| from a concentric sphere of radius b,
    # with parallel normals: acc = comp = |a - b|, N.C. = 1. Sample spacing adds < 1e-3.
    m = evaluate_mesh_pair(sphere(1.0), sphere(1.1), n_samples=100_000, threshold=0.05, seed=3)
    assert m.accuracy == pytest.approx(0.1, abs=1.5e-3)
    assert m.completion == pytest.approx(0.1, abs=1.5e-3)
    assert m.chamfer == pytest.approx(0.1, abs=1.5e-3)
    assert m.precision == 0.0 and m.recall == 0.0 and m.fscore == 0.0
    assert m.normal_consistency == pytest.approx(1.0, abs=2e-3)
    m2 = evaluate_mesh_pair(sphere(1.0), sphere(1.1), n_samples=50_000, threshold=0.15, seed=3)
    assert m2.precision == 1.0 and m2.recall == 1.0 and m2.fscore == 1.0


def test_identical_meshes():
    # identical samples (gt_seed = seed): exactly 0
    m = evaluate_mesh_pair(sphere(0.5), sphere(0.5), n_samples=20_000, gt_seed=0)
    assert m.accuracy == 0.0 and m.completion == 0.0 and m.chamfer == 0.0
    assert m.fscore == 1.0
    assert m.normal_consistency == pytest.approx(1.0, abs=1e-12)
    # independent samples (default, as MonoSDF): only the sample spacing remains: mean 2D Poisson
    # nearest-neighbour distance 0.5 / sqrt(density) = 2.8 mm for 100k points on pi m^2
    m = evaluate_mesh_pair(sphere(0.5), sphere(0.5), n_samples=100_000)
    assert m.accuracy == pytest.approx(0.5 / np.sqrt(1e5 / np.pi), rel=0.05)
    assert m.completion == pytest.approx(m.accuracy, rel=0.05) and m.fscore == 1.0
    assert m.normal_consistency > 0.999


@pytest.mark.parametrize("d", [0.01, 0.03, 0.2])
def test_shifted_plane_every_distance_is_d(d):
    plane = trimesh.creation.box((1.0, 1.0, 1e-9))
    plane = trimesh.Trimesh(plane.vertices, plane.faces[plane.face_normals[:, 2] > 0.5], process=False)
    moved = plane.copy()
    moved.apply_translation([0, 0, d])
    m = evaluate_mesh_pair(moved, plane, n_samples=20_000, threshold=0.05, gt_seed=0)
    assert m.accuracy == pytest.approx(d, abs=1e-9) and m.completion == pytest.approx(d, abs=1e-9)
    expected = 1.0 if d < 0.05 else 0.0
    assert m.precision == expected and m.recall == expected
    assert m.normal_consistency == pytest.approx(1.0)


def test_point_metrics_hand_values_and_formulas():
    p = np.array([[0.0, 0, 0], [1, 0, 0], [3, 0, 0]])
    g = np.array([[0.0, 0, 0.04], [1, 0, 0.5]])
    m = point_metrics(p, g, threshold=0.05)
    # pred->gt: 0.04, 0.5, sqrt(4+0.25); gt->pred: 0.04, 0.5
    acc = (0.04 + 0.5 + np.sqrt(4.25)) / 3
    assert m.accuracy == pytest.approx(acc)
    assert m.completion == pytest.approx(0.27)
    assert m.chamfer == pytest.approx((acc + 0.27) / 2)
    assert m.precision == pytest.approx(1 / 3) and m.recall == pytest.approx(0.5)
    assert m.fscore == pytest.approx(2 * (1 / 3) * 0.5 / (1 / 3 + 0.5))
    assert np.isnan(m.normal_consistency)
    d = m.as_dict()
    assert set(d) >= {"accuracy", "completion", "chamfer", "precision", "recall", "fscore", "normal_consistency"}
    assert isinstance(d["n_pred"], int)


def test_normal_consistency_ignores_orientation_and_detects_tilt():
    rng = np.random.default_rng(0)
    p = rng.random((500, 3))
    n = np.tile([0.0, 0, 1], (500, 1))
    assert point_metrics(p, p, 0.05, n, -n).normal_consistency == pytest.approx(1.0)
    tilt = np.tile([0.0, np.sin(0.3), np.cos(0.3)], (500, 1))
    assert point_metrics(p, p, 0.05, n, tilt).normal_consistency == pytest.approx(np.cos(0.3))


def test_invariances_order_dtype():
    rng = np.random.default_rng(5)
    p, g = rng.random((3000, 3)), rng.random((2000, 3)) + 0.02
    base = point_metrics(p, g)
    perm = point_metrics(p[rng.permutation(3000)], g[rng.permutation(2000)])
    f32 = point_metrics(p.astype(np.float32), g.astype(np.float32))
    for k in ("accuracy", "completion", "precision", "recall", "fscore"):
        assert getattr(perm, k) == pytest.approx(getattr(base, k), abs=1e-12)
        assert getattr(f32, k) == pytest.approx(getattr(base, k), abs=1e-6)


def test_duplicated_vertices_and_faces_do_not_change_the_surface():
    s = sphere(0.7)
    ref = sphere(0.72)
    # duplicated vertices (faces re-pointed to the copies, same face list): identical samples
    v2 = np.concatenate([s.vertices, s.vertices])
    dup_v = trimesh.Trimesh(v2, s.faces + len(s.vertices), process=False)
    assert evaluate_mesh_pair(dup_v, ref, n_samples=20_000) == evaluate_mesh_pair(s, ref, n_samples=20_000)
    np.testing.assert_array_equal(sample_mesh_surface(dup_v, 100)[0], sample_mesh_surface(s, 100)[0])
    # every face duplicated: same area-weighted surface distribution -> same metrics up to sampling noise
    dup_f = trimesh.Trimesh(v2, np.concatenate([s.faces, s.faces + len(s.vertices)]), process=False)
    a = evaluate_mesh_pair(dup_f, ref, n_samples=50_000, seed=1)
    b = evaluate_mesh_pair(s, ref, n_samples=50_000, seed=1)
    assert a.accuracy == pytest.approx(b.accuracy, abs=5e-4)
    assert a.completion == pytest.approx(b.completion, abs=5e-4)
    assert a.fscore == pytest.approx(b.fscore, abs=1e-2)


def test_sampling_is_seeded_and_on_surface():
    s = sphere(0.5)
    a, na = sample_mesh_surface(s, 1000, seed=7)
    b, _ = sample_mesh_surface(s, 1000, seed=np.random.default_rng(7))
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, sample_mesh_surface(s, 1000, seed=8)[0])
    r = np.linalg.norm(a, axis=1)
    assert np.all(r <= 0.5 + 1e-9) and np.all(r > 0.499)
    np.testing.assert_allclose(np.linalg.norm(na, axis=1), 1.0)


def test_empty_and_degenerate_meshes_raise():
    with pytest.raises(ValueError, match="empty"):
        sample_mesh_surface(trimesh.Trimesh(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)), 10)
    line = trimesh.Trimesh(np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]]), np.array([[0, 1, 2]]), process=False)
    with pytest.raises(ValueError, match="positive"):
        sample_mesh_surface(line, 10)
    with pytest.raises(TypeError):
        sample_mesh_surface(np.zeros((3, 3)), 10)


def test_nan_vertices_drop_touching_faces():
    s = sphere(0.5)
    v = s.vertices.copy()
    v[0] = np.nan
    m = trimesh.Trimesh(v, s.faces, process=False)
    vv, ff = clean_mesh(m)
    touching = (s.faces == 0).any(1)
    assert ff.shape[0] == len(s.faces) - touching.sum()
    p, _ = sample_mesh_surface(m, 2000)
    assert np.all(np.isfinite(p))
    all_nan = trimesh.Trimesh(np.full_like(v, np.nan), s.faces, process=False)
    with pytest.raises(ValueError):
        sample_mesh_surface(all_nan, 10)


def test_point_metrics_validation():
    with pytest.raises(ValueError, match="threshold"):
        point_metrics(np.zeros((2, 3)), np.zeros((2, 3)), threshold=0.0)
    with pytest.raises(ValueError, match="both"):
        point_metrics(np.zeros((2, 3)), np.zeros((2, 3)), pred_normals=np.ones((2, 3)))
    with pytest.raises(ValueError, match="shape"):
        point_metrics(np.zeros((2, 3)), np.zeros((2, 3)), 0.05, np.ones((3, 3)), np.ones((2, 3)))


def test_real_bunny_self_and_perturbed(real_mesh):
    bunny = real_mesh("bunny.ply")
    bunny = trimesh.Trimesh(bunny.vertices / 0.156, bunny.faces, process=False)  # ~1 m across
    same = evaluate_mesh_pair(bunny, bunny, n_samples=30_000, gt_seed=0)
    assert same.chamfer == 0.0 and same.fscore == 1.0
    moved = bunny.copy()
    moved.apply_translation([0.02, 0, 0])
    m = evaluate_mesh_pair(moved, bunny, n_samples=30_000, gt_seed=0)
    assert 0.0 < m.accuracy <= 0.02 + 1e-9 and 0.0 < m.completion <= 0.02 + 1e-9  # nearest <= own copy
    assert isinstance(m, MeshMetrics) and m.fscore > 0.95
