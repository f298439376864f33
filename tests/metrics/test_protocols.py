import numpy as np
import pytest
import trimesh

from metrics.culling import crop_mesh_to_bbox, cull_mesh_to_frusta, cull_mesh_to_visible, gt_bounding_box, points_in_frusta
from metrics.dtu import DTUParams, dtu_chamfer, dtu_gt_points, radius_downsample, sample_mesh_dtu
from metrics.mesh import EmptyReconstructionError
from metrics.protocols import cull_replica_gt, evaluate_mesh_replica, evaluate_mesh_scannet, sample_replica_gt
from metrics.render import render_depth_maps
from metrics.tsdf import _block_coords, _touched_block_keys, tsdf_refuse, voxel_downsample


def test_frustum_test_and_depth_rendering_are_z_depth():
    K = np.array([[50.0, 0, 31.5], [0, 50.0, 23.5], [0, 0, 1]])
    c2w = np.eye(4)
    pts = np.array([[0, 0, 2.0], [0, 0, -2.0], [10, 0, 2.0], [0.6, 0.45, 1.0]])
    assert points_in_frusta(pts, K, c2w, 48, 64).tolist() == [True, False, False, True]
    wall = trimesh.Trimesh([[-5, -5, 3.0], [5, -5, 3], [5, 5, 3], [-5, 5, 3]], [[0, 1, 2], [0, 2, 3]], process=False)
    d = render_depth_maps(wall, K, c2w[None], 48, 64)
    np.testing.assert_allclose(d, 3.0, rtol=1e-6)  # a fronto-parallel plane has constant z-depth


def test_views_seeing_counts_each_view_in_frame_and_in_front_of_its_depth():
    """Two cameras 1 m apart looking along +z at a wall at z = 3: a point on the wall in both frames is
    seen by both, one behind the wall by none, one beside the first camera's frame only by the second."""
    from metrics.culling import points_visible, views_seeing

    K = np.array([[50.0, 0, 31.5], [0, 50.0, 23.5], [0, 0, 1]])
    c2w = np.stack([np.eye(4), np.eye(4)])
    c2w[1, 0, 3] = 1.0
    depth = np.full((2, 48, 64), 3.0)
    pts = np.array([[0.5, 0.0, 3.0], [0.5, 0.0, 3.5], [2.9, 0.0, 3.0]])
    seen = views_seeing(pts, K, c2w, 48, 64, depth, tol=0.02)
    assert seen.tolist() == [[True, False, False], [True, False, True]]
    np.testing.assert_array_equal(points_visible(pts, K, c2w, 48, 64, depth, tol=0.02), seen.any(0))


def test_cull_and_crop(ring_cameras):
    K, c2w, H, W = ring_cameras
    box = trimesh.creation.box((0.5, 0.5, 0.5))
    far = trimesh.creation.box((0.5, 0.5, 0.5))
    far.apply_translation([0, 0, 30.0])  # above every camera: outside all frusta
    both = trimesh.util.concatenate([box, far])
    culled = cull_mesh_to_frusta(both, K, c2w, H, W)
    assert len(culled.faces) == len(box.faces) and culled.vertices[:, 2].max() < 1
    to_box, half = gt_bounding_box(box, 1.05)
    np.testing.assert_allclose(np.sort(half), [0.2625] * 3)
    assert len(crop_mesh_to_bbox(both, to_box, half).faces) == len(box.faces)


def test_visibility_culling_removes_hidden_faces(ring_cameras):
    K, c2w, H, W = ring_cameras
    from metrics.culling import subdivide_mesh

    box = subdivide_mesh(trimesh.creation.box((0.6, 0.6, 0.6)), 0.05)
    vis = cull_mesh_to_visible(box, K, c2w, H, W)
    # cameras are above the box (z = 0.8 m): the bottom face (z = -0.3) is never seen; only bottom
    # triangles near the rim survive (a pixel covers ~5 cm at 2.5 m, so vertices within a pixel of a
    # seen side face pass the occlusion test)
    bottom = vis.face_normals[:, 2] < -0.99
    near_rim = (np.abs(vis.vertices[:, :2]) > 0.3 - 0.1).any(1)
    assert near_rim[vis.faces[bottom]].any(1).all()
    n_bottom = (box.face_normals[:, 2] < -0.99).sum()
    assert bottom.sum() < 0.5 * n_bottom and 0 < len(vis.faces) < len(box.faces)


def test_replica_protocol_identical_and_shifted(ring_cameras):
    K, c2w, H, W = ring_cameras
    gt = trimesh.creation.icosphere(4, radius=0.5)
    same = evaluate_mesh_replica(gt, gt, K, c2w, H, W, n_samples=30_000)
    assert same.fscore == 1.0 and same.accuracy < 8e-3 and same.normal_consistency > 0.99
    big = trimesh.creation.icosphere(4, radius=0.53)
    m = evaluate_mesh_replica(big, gt, K, c2w, H, W, n_samples=30_000)
    assert m.accuracy == pytest.approx(0.03, abs=3e-3) and m.completion == pytest.approx(0.03, abs=4e-3)
    far = trimesh.creation.icosphere(2, radius=0.5)
    far.apply_translation([0, 0, 40.0])
    nothing = evaluate_mesh_replica(far, gt, K, c2w, H, W, n_samples=1000)  # no camera sees it: a result, F = 0
    assert (nothing.precision, nothing.recall, nothing.fscore, nothing.n_pred) == (0.0, 0.0, 0.0, 0)
    assert np.isnan(nothing.accuracy) and np.isnan(nothing.completion) and np.isnan(nothing.normal_consistency)
    assert nothing.n_gt == 1000


def test_replica_prepared_gt_gives_identical_metrics(ring_cameras):
    """The GT-side cache (the culled surface once per scene, its samples once per seed, evaluate many
    snapshots) is exactly the one-shot protocol, for every seed."""
    K, c2w, H, W = ring_cameras
    gt = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    pred = trimesh.creation.box(extents=(1.04, 1.0, 0.98))
    for visibility in ("visible", "frustum"):
        surface = cull_replica_gt(gt, K, c2w, H, W, gt_visibility=visibility)
        for seed in (3, 4):
            kw = dict(n_samples=20_000, gt_visibility=visibility, seed=seed)
            once = evaluate_mesh_replica(pred, gt, K, c2w, H, W, **kw).as_dict()
            prepared = sample_replica_gt(surface, 20_000, seed)
            cached = evaluate_mesh_replica(pred, None, K, c2w, H, W, prepared_gt=prepared, **kw).as_dict()
            assert once == cached


def test_tsdf_refuse_keeps_a_plane_seen_by_one_view():
    """One camera, one fronto-parallel wall: the fused surface exists and lies on the wall (open3d's
    VoxelBlockGrid drops voxels seen by < 3 frames by default; we keep every observed one)."""
    K = np.array([[50.0, 0, 31.5], [0, 50.0, 23.5], [0, 0, 1]])
    wall = trimesh.Trimesh([[-5, -5, 2.0], [5, -5, 2], [5, 5, 2], [-5, 5, 2]], [[0, 1, 2], [0, 2, 3]], process=False)
    fused = tsdf_refuse(wall, K, np.eye(4)[None], 48, 64, voxel_size=0.02, sdf_trunc=0.06)
    assert len(fused.faces) > 100
    np.testing.assert_allclose(fused.vertices[:, 2], 2.0, atol=0.011)


def test_touched_blocks_match_a_per_point_loop():
    """The vectorised block touch (8 corners of each point's truncation cube, one int64 key per block)
    equals a plain loop over points and their block ranges."""
    rng = np.random.default_rng(0)
    depth = rng.uniform(0.5, 3.0, (6, 8)) * (rng.random((6, 8)) > 0.2)
    depth[0, 0] = 7.0  # beyond depth_trunc: ignored
    K = np.array([[5.0, 0, 3.5], [0, 5.0, 2.5], [0, 0, 1]])
    c2w = np.eye(4)
    c2w[:3, 3] = [-1.3, 0.2, 0.7]
    got = {tuple(b) for b in _block_coords(_touched_block_keys(depth, K, c2w, 5.0, 0.06, 0.32)).tolist()}
    want = set()
    for v, u in zip(*np.nonzero((depth > 0) & (depth <= 5.0))):
        p = np.linalg.inv(K) @ np.array([u, v, 1.0]) * depth[v, u] + c2w[:3, 3]
        lo, hi = np.floor((p - 0.06) / 0.32).astype(int), np.floor((p + 0.06) / 0.32).astype(int)
        want |= {(x, y, z) for x in range(lo[0], hi[0] + 1) for y in range(lo[1], hi[1] + 1) for z in range(lo[2], hi[2] + 1)}
    assert got == want and any(min(b) < 0 for b in got)


def test_scannet_protocol(ring_cameras):
    K, c2w, H, W = ring_cameras
    gt = trimesh.creation.box((0.8, 0.8, 0.8))
    refused = tsdf_refuse(gt, K, c2w, H, W, voxel_size=0.02, sdf_trunc=0.06)
    assert len(refused.faces) > 0 and np.abs(refused.vertices).max() < 0.45
    kw = dict(tsdf_voxel=0.02, tsdf_trunc=0.06)
    same = evaluate_mesh_scannet(gt, gt, K, c2w, H, W, **kw)
    assert same.accuracy < 1e-6 and same.fscore == 1.0 and np.isnan(same.normal_consistency)
    moved = gt.copy()
    moved.apply_translation([0.1, 0, 0])
    m = evaluate_mesh_scannet(moved, gt, K, c2w, H, W, **kw)
    assert 0.03 < m.chamfer < 0.1 and m.fscore < 1.0
    far = gt.copy()
    far.apply_translation([0, 0, 40.0])
    nothing = evaluate_mesh_scannet(far, gt, K, c2w, H, W, **kw)  # re-fuses to nothing: F = 0, distances undefined
    assert (nothing.fscore, nothing.recall, nothing.n_pred) == (0.0, 0.0, 0) and np.isnan(nothing.chamfer)
    assert nothing.n_gt == same.n_gt


def test_dtu_sampling_downsampling_and_chamfer(ring_cameras):
    K, c2w, H, W = ring_cameras
    params = DTUParams.scaled(object_size=0.6, image_downscale=20)  # density ~7 mm, cut ~34 mm
    assert params.max_dist == pytest.approx(20 * 0.6 / 350)
    sq = trimesh.Trimesh([[0, 0, 0.0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], process=False)
    pts = sample_mesh_dtu(sq, 0.1)
    assert np.all(pts[:, 0] + pts[:, 1] <= 1 + 1e-12) and len(pts) == 3 + 45
    down = radius_downsample(pts, 0.15, seed=0)
    assert len(down) < len(pts)
    gt = trimesh.creation.icosphere(4, radius=0.3)
    gpts = dtu_gt_points(gt, K, c2w, H, W, params)
    res = dtu_chamfer(gt, gpts, K, c2w, H, W, params, gt_mesh=gt)
    assert res.chamfer < params.density and res.d2s < params.density
    big = trimesh.creation.icosphere(4, radius=0.31)
    r2 = dtu_chamfer(big, gpts, K, c2w, H, W, params, gt_mesh=gt)
    assert r2.chamfer == pytest.approx(0.01, abs=params.density / 2)
    # ground plane z > 0.1: only the cap enters s2d
    r3 = dtu_chamfer(big, gpts, K, c2w, H, W, params, gt_mesh=gt, ground_plane=[0, 0, 1, -0.1])
    assert r3.n_gt < res.n_gt
    with pytest.raises(ValueError):
        dtu_chamfer(big, gpts, K, c2w, H, W, params)  # no depth maps and no gt mesh
    with pytest.raises(ValueError, match="max_points"):
        sample_mesh_dtu(gt, 1e-5, max_points=1000)


def test_lost_dtu_reconstruction_is_one_error_type(ring_cameras):
    """An empty mesh and a mesh nowhere near the object are the same outcome (the surface was lost):
    one exception type, a ValueError subclass, that the tables and tests tell from bad input."""
    K, c2w, H, W = ring_cameras
    params = DTUParams.scaled(object_size=0.6, image_downscale=20)
    gt = trimesh.creation.icosphere(3, radius=0.3)
    gpts = dtu_gt_points(gt, K, c2w, H, W, params)
    far = trimesh.creation.icosphere(2, radius=0.05)
    far.apply_translation([3.0, 0, 0])  # a few stray triangles outside the evaluation box
    empty = trimesh.Trimesh(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64), process=False)
    for mesh, msg in ((far, "evaluation bounding box"), (empty, "pred_mesh is empty")):
        with pytest.raises(EmptyReconstructionError, match=msg):
            dtu_chamfer(mesh, gpts, K, c2w, H, W, params, gt_mesh=gt)
    with pytest.raises(EmptyReconstructionError):
        evaluate_mesh_scannet(empty, gt, K, c2w, H, W)
    with pytest.raises(ValueError) as info:  # a bad GT is bad input, not a lost reconstruction
        dtu_chamfer(far, np.zeros((0, 3)), K, c2w, H, W, params, gt_mesh=gt)
    assert not isinstance(info.value, EmptyReconstructionError)


def test_real_lamp_thin_structures(real_mesh, ring_cameras):
    K, c2w, H, W = ring_cameras
    lamp = real_mesh("chair_model.obj")
    lamp = trimesh.Trimesh(lamp.vertices - lamp.bounds.mean(0), lamp.faces, process=False)
    m = evaluate_mesh_replica(lamp, lamp, K, c2w, H, W, n_samples=20_000)
    assert m.fscore > 0.99 and m.chamfer < 0.01


def test_world_to_cam_matches_its_per_camera_twin(ring_cameras):
    from metrics.culling import _world_to_cam, _world_to_cam_reference

    _, c2w, _, _ = ring_cameras
    pts = np.random.default_rng(0).normal(size=(1000, 3))
    np.testing.assert_allclose(_world_to_cam(pts, np.asarray(c2w, dtype=np.float64)),
                               _world_to_cam_reference(pts, np.asarray(c2w, dtype=np.float64)), atol=1e-12)


def test_fusion_blocks_keep_monosdf_width_in_metres(ring_cameras):
    """MonoSDF's 16-voxel units of 1 cm are 16 cm wide: 16 voxels at 1 cm, 8 at 2 cm; the ScanNet
    protocol's re-fusion uses that block (same mesh as tsdf_refuse called with it)."""
    from metrics.tsdf import block_resolution_for

    assert [block_resolution_for(v) for v in (0.01, 0.02, 0.015, 0.5)] == [16, 8, 11, 1]
    K, c2w, H, W = ring_cameras
    gt = trimesh.creation.box((0.8, 0.8, 0.8))
    moved = gt.copy()
    moved.apply_translation([0.02, 0, 0])
    kw = dict(voxel_size=0.02, sdf_trunc=0.06)
    m = evaluate_mesh_scannet(moved, gt, K, c2w, H, W, tsdf_voxel=0.02, tsdf_trunc=0.06)
    pv = voxel_downsample(np.asarray(tsdf_refuse(moved, K, c2w, H, W, block_resolution=8, **kw).vertices), 0.02)
    assert m.n_pred == pv.shape[0]


def test_prepared_gt_index_gives_identical_metrics(ring_cameras):
    """The GT side prepared once (downsampled points + nearest-neighbour index) is the one-shot protocol."""
    from metrics.nn import NearestNeighborIndex
    from metrics.protocols import scannet_gt_points

    K, c2w, H, W = ring_cameras
    gt = trimesh.creation.box((0.8, 0.8, 0.8))
    pred = trimesh.creation.box((0.84, 0.8, 0.78))
    kw = dict(tsdf_voxel=0.02, tsdf_trunc=0.06)
    once = evaluate_mesh_scannet(pred, gt, K, c2w, H, W, **kw).as_dict()
    index = NearestNeighborIndex(scannet_gt_points(gt, K, c2w, H, W, **kw))
    assert evaluate_mesh_scannet(pred, None, K, c2w, H, W, gt_index=index, **kw).as_dict() == pytest.approx(once, rel=0, nan_ok=True)
