"""MonoSDF's DTU mask culling (metrics/mask_cull.py): against a per-vertex loop, and on a built case."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import trimesh

from metrics.mask_cull import cull_mesh_by_masks, dilate_masks, dilation_radius, vertices_kept
from metrics.render import render_depth_maps


def _kept_reference(vertices, masks, K, c2w):
    """Slow twin: one vertex, one view at a time, written as MonoSDF's cull_scan reads (normalised
    coordinates strictly inside (-1, 1) -> the dilated mask at the nearest pixel must be set)."""
    N, H, W = masks.shape
    out = []
    for x in vertices:
        ok = True
        for i in range(N):
            p = np.linalg.inv(c2w[i]) @ np.append(x, 1.0)
            q = K[i] @ p[:3]
            u, v = q[0] / (q[2] + 1e-6), q[1] / (q[2] + 1e-6)
            nu, nv = u / (W - 1) * 2 - 1, v / (H - 1) * 2 - 1
            if -1 < nu < 1 and -1 < nv < 1 and not masks[i][int(np.round(v)), int(np.round(u))]:
                ok = False
        out.append(ok)
    return np.array(out)


def test_vectorised_matches_the_loop(ring_cameras):
    K, c2w, H, W = ring_cameras
    rng = np.random.default_rng(0)
    masks = rng.random((len(c2w), H, W)) > 0.3
    verts = rng.uniform(-1.5, 1.5, (400, 3))
    Ks = np.repeat(K[None], len(c2w), 0)
    assert np.array_equal(vertices_kept(verts, masks, Ks, c2w), _kept_reference(verts, masks, Ks, c2w))


def test_floor_outside_the_masks_is_culled_the_object_kept(ring_cameras):
    K, c2w, H, W = ring_cameras
    Ks = np.repeat(K[None], len(c2w), 0)
    obj = trimesh.creation.icosphere(subdivisions=3, radius=0.4)
    masks = render_depth_maps(obj, Ks, c2w, H, W) > 0  # the object's silhouettes
    floor = trimesh.creation.box((6.0, 6.0, 0.01))
    floor.apply_translation([0.0, 0.0, -0.6])
    floor = floor.subdivide().subdivide().subdivide()
    both = trimesh.util.concatenate([obj, floor])
    culled = cull_mesh_by_masks(both, masks, Ks, c2w, radius=dilation_radius(W))
    assert dilation_radius(W) == 1 and dilation_radius(1600) == 12
    # every sphere vertex survives (inside its own silhouette in every view)
    kept = {tuple(np.round(v, 9)) for v in culled.vertices}
    assert all(tuple(np.round(v, 9)) in kept for v in obj.vertices)
    # the floor far from the object is gone; only floor parts under the dilated silhouettes remain
    far_floor = np.linalg.norm(culled.vertices[:, :2], axis=1) > 1.0
    assert not far_floor.any()
    assert len(culled.faces) < len(both.faces) and np.isfinite(culled.vertices).all()


def test_dilation_grows_masks_and_empty_masks_cull_all_visible(ring_cameras):
    K, c2w, H, W = ring_cameras
    m = np.zeros((1, H, W), bool)
    m[0, 20, 30] = True
    assert dilate_masks(m, 2).sum() == 13  # a disk of radius 2
    Ks = np.repeat(K[None], len(c2w), 0)
    obj = trimesh.creation.icosphere(subdivisions=2, radius=0.4)
    culled = cull_mesh_by_masks(obj, np.zeros((len(c2w), H, W), bool), Ks, c2w, radius=1)
    assert len(culled.faces) == 0


@pytest.mark.slow
def test_dtu_protocol_with_monosdf_culling_drops_a_floater(monkeypatch, tmp_path):
    """End to end through bench.evaluate: the GT mesh plus a floater outside every mask. With
    ``dtu.cull: monosdf`` the floater is culled before the Chamfer step; both CDs are finite."""
    import bench.evaluate as ev
    from bench.data.datasets import load_dataset
    from bench.data.errors import BenchInputError
    from methods.base import Snapshot

    scene = load_dataset("dtu_like_0", "tiny")
    gt = scene.load_gt_mesh()
    lo, hi = np.asarray(scene.metadata["layout"]["object_bounds_m"])
    floater = trimesh.creation.icosphere(subdivisions=2, radius=0.05 * float((hi - lo).max()))
    floater.apply_translation(lo + (hi - lo) * np.array([1.1, 0.5, 0.5]))
    mesh = trimesh.util.concatenate([gt, floater])
    snap = Snapshot(fraction=1.0, iterations=1, seconds=0.0, mesh=mesh)
    real = ev.protocol_params

    def with_cull(cull):
        monkeypatch.setattr(ev, "protocol_params", lambda protocol, scale: dataclasses.replace(real(protocol, scale), cull=cull))
        return ev.evaluate_snapshot(snap, scene, "dtu", "tiny")["cd"]

    plain, culled = with_cull("none"), with_cull("monosdf")
    assert np.isfinite(plain) and np.isfinite(culled) and culled < plain  # measured 0.0021 -> 0.0013 m
    bad = tmp_path / "protocols.yaml"  # a bad value in the protocols file: an error naming the file and the key
    bad.write_text(ev.PROTOCOLS_FILE.read_text().replace("cull: none}", "cull: sparseneus}"))
    with pytest.raises(BenchInputError, match=r"protocols.yaml \(dtu, scale 'tiny'\).*'cull' must be one of"):
        real("dtu", "tiny", path=bad)
