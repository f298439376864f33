"""`bench scenes downsize`: each map's resampling against a per-pixel loop, intrinsics against
projecting points, and a folder round trip in every format."""

from __future__ import annotations

import numpy as np
import pytest
from fmt_helpers import FORMATS, write

from bench.cli import main
from bench.data.formats import load_scene
from bench.data.formats.downsize import downsize_depth, downsize_ids, downsize_intrinsics, downsize_normal, downsize_rgb


def _loop(arr, n, fn):
    v, h, w = arr.shape[:3]
    out = []
    for i in range(v):
        rows = []
        for y in range(h // n):
            rows.append([fn(arr[i, y * n:(y + 1) * n, x * n:(x + 1) * n]) for x in range(w // n)])
        out.append(rows)
    return np.asarray(out)


def _median_valid(block):
    vals = block[block > 0]
    return float(np.median(vals)) if vals.size * 2 >= block.size else 0.0


def test_maps_match_the_per_block_loop():
    rng = np.random.default_rng(0)
    rgb = rng.random((2, 9, 12, 3)).astype(np.float32)
    np.testing.assert_allclose(downsize_rgb(rgb, 3), _loop(rgb, 3, lambda b: b.reshape(-1, 3).mean(0)), atol=1e-6)
    depth = np.where(rng.random((2, 10, 14)) < 0.3, 0.0, rng.random((2, 10, 14)) + 1).astype(np.float32)
    np.testing.assert_allclose(downsize_depth(depth, 2), _loop(depth, 2, _median_valid), atol=1e-6)
    n = rng.normal(size=(1, 6, 6, 3)).astype(np.float32)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    want = _loop(n, 3, lambda b: b.reshape(-1, 3).sum(0) / np.linalg.norm(b.reshape(-1, 3).sum(0)))
    np.testing.assert_allclose(downsize_normal(n, 3), want, atol=1e-5)
    ids = rng.integers(0, 5, (1, 8, 8)).astype(np.int32)
    np.testing.assert_array_equal(downsize_ids(ids, 4), _loop(ids, 4, lambda b: b[2, 2]))


def test_intrinsics_keep_the_projection_of_points():
    """A point projecting to source pixel coordinate u lands at (u + 0.5) / n - 0.5 after downsizing."""
    K = np.array([[100.0, 0, 63.5], [0, 90.0, 47.5], [0, 0, 1]])
    K2 = downsize_intrinsics(K, 4)
    X = np.array([0.3, -0.2, 2.0])
    u = K @ X / X[2]
    u2 = K2 @ X / X[2]
    np.testing.assert_allclose(u2[:2], (u[:2] + 0.5) / 4 - 0.5, atol=1e-12)


@pytest.mark.parametrize("fmt", FORMATS)
def test_folder_round_trip_every_format(tmp_path, scene, fmt):
    src = write(scene, tmp_path / "src", fmt)
    dst = tmp_path / "dst"
    assert main(["scenes", "downsize", str(src), str(dst), "--factor", "2"]) == 0
    small = load_scene(dst)
    assert small.source_format == fmt and small.num_views == scene.num_views
    assert (small.height, small.width) == (scene.height // 2, scene.width // 2)
    np.testing.assert_allclose(small.cam_to_world, scene.cam_to_world, atol=1e-6)
    if scene.gt_depth is not None and small.gt_depth is not None:
        assert np.isfinite(small.gt_depth).all() and (small.gt_depth >= 0).all()


def test_factor_too_large_is_one_clear_error(tmp_path, scene, capsys):
    src = write(scene, tmp_path / "src", "scannet")
    assert main(["scenes", "downsize", str(src), str(tmp_path / "dst"), "--factor", "10"]) == 2
    assert "--factor 10 leaves" in capsys.readouterr().err
    assert not (tmp_path / "dst").exists()
