"""Scene -> write -> load -> equal, for every format; and loading with only the real format's files."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from fmt_helpers import FORMATS, quantised, strip_extras, write
from PIL import Image

from bench.data.formats import detect_format, load_scene
from bench.data.formats.llff import resize_nearest, scale_intrinsics


def assert_cameras(loaded, scene):
    np.testing.assert_allclose(loaded.cam_to_world, scene.cam_to_world, atol=1e-6, rtol=0)
    np.testing.assert_allclose(loaded.intrinsics, scene.intrinsics, atol=1e-6, rtol=0)
    assert loaded.cam_to_world.dtype == np.float64 and loaded.intrinsics.dtype == np.float64


@pytest.mark.parametrize("fmt", FORMATS)
def test_roundtrip(tmp_path, scene, gt_mesh, fmt):
    root = write(scene, tmp_path / fmt, fmt, gt_mesh=gt_mesh)
    assert detect_format(root) == fmt
    loaded = load_scene(root)
    assert loaded.source_format == fmt and loaded.root == root
    assert (loaded.name, loaded.kind) == (scene.name, scene.kind)
    assert_cameras(loaded, scene)
    np.testing.assert_allclose(loaded.scale_mat, scene.scale_mat, atol=1e-12, rtol=0)
    np.testing.assert_array_equal(loaded.images, quantised(scene.images))
    assert loaded.images.dtype == np.float32
    np.testing.assert_array_equal(loaded.mono_depth, scene.mono_depth)
    np.testing.assert_allclose(loaded.mono_normal, scene.mono_normal, atol=1e-6, rtol=0)
    np.testing.assert_array_equal(loaded.gt_depth, scene.gt_depth)
    np.testing.assert_array_equal(loaded.gt_normal, scene.gt_normal)
    np.testing.assert_array_equal(loaded.gt_instance, scene.gt_instance)
    np.testing.assert_array_equal(loaded.seg_masks, scene.seg_masks)
    assert loaded.gt_instance.dtype == np.int32 and loaded.seg_masks.dtype == np.int32
    assert loaded.seg_background == scene.seg_background
    assert loaded.instances == scene.instances
    assert set(loaded.splits) == set(scene.splits)
    for k in scene.splits:
        np.testing.assert_array_equal(loaded.splits[k], scene.splits[k])
    meta = {k: v for k, v in loaded.metadata.items() if not k.startswith("llff_")}
    assert meta == scene.metadata
    mesh = loaded.load_gt_mesh()
    np.testing.assert_allclose(mesh.vertices, gt_mesh.vertices, atol=1e-6)
    np.testing.assert_array_equal(mesh.faces, gt_mesh.faces)


def test_dtu_object_mask(tmp_path, scene):
    from bench.data.formats.dtu import load_object_masks

    root = write(scene, tmp_path / "dtu", "dtu")
    masks = load_object_masks(root)
    np.testing.assert_array_equal(masks, np.isin(scene.gt_instance, [3, 4]))
    assert sorted(p.name for p in (root / "mask").iterdir())[:2] == ["000.png", "001.png"]


def test_replica_mask_invalidates_mono_depth(tmp_path, scene):
    root = write(scene, tmp_path / "replica", "replica")
    mask = np.load(root / "000001_mask.npy")
    np.testing.assert_array_equal(mask, scene.mono_depth[1] > 0)
    mask[5, 5] = False
    np.save(root / "000001_mask.npy", mask)
    loaded = load_scene(root)
    assert loaded.mono_depth[1, 5, 5] == 0 and scene.mono_depth[1, 5, 5] > 0


def test_mono_normal_storage_is_monosdf(tmp_path, scene):
    root = write(scene, tmp_path / "s", "scannet")
    stored = np.load(root / "000002_normal.npy")
    assert stored.shape == (3, scene.height, scene.width) and stored.dtype == np.float32
    assert stored.min() >= 0 and stored.max() <= 1
    # MonoSDF decoding (x * 2 - 1) gives our OpenCV camera-frame normal, no axis flip
    np.testing.assert_allclose(np.transpose(stored, (1, 2, 0)) * 2 - 1, scene.mono_normal[2], atol=1e-6)


def test_llff_factor(tmp_path, scene):
    root = write(scene, tmp_path / "llff", "llff", factors=(2, 4))
    assert sorted(p.name for p in (root / "images_2").iterdir())[0] == "IMG_0000.png"
    loaded = load_scene(root, factor=2)
    h, w = scene.height // 2, scene.width // 2
    assert (loaded.height, loaded.width) == (h, w)
    img8 = np.round(scene.images[1] * 255).astype(np.uint8)
    small = np.asarray(Image.fromarray(img8).resize((w, h), Image.Resampling.BOX), dtype=np.float32) / 255
    np.testing.assert_array_equal(loaded.images[1], small)
    np.testing.assert_allclose(loaded.intrinsics, scale_intrinsics(scene.intrinsics, 0.5, 0.5), atol=1e-9)
    np.testing.assert_allclose(loaded.intrinsics[0, :2, 2], [(w - 1) / 2, (h - 1) / 2], atol=1e-12)
    np.testing.assert_allclose(loaded.intrinsics[0, 0, 0], scene.intrinsics[0, 0, 0] / 2)
    np.testing.assert_allclose(loaded.cam_to_world, scene.cam_to_world, atol=1e-6)
    # extras resampled by nearest: output pixel (r, c) <- source (2r + 1, 2c + 1)
    np.testing.assert_array_equal(loaded.gt_instance, scene.gt_instance[:, 1::2, 1::2])
    np.testing.assert_array_equal(loaded.gt_depth, resize_nearest(scene.gt_depth, (h, w)))
    np.testing.assert_allclose(loaded.mono_normal, scene.mono_normal[:, 1::2, 1::2], atol=1e-6)
    assert load_scene(root, factor=4).width == scene.width // 4


def test_llff_bounds_are_gt_depth_percentiles(tmp_path, scene):
    root = write(scene, tmp_path / "llff", "llff")
    pb = np.load(root / "poses_bounds.npy")
    assert pb.shape == (scene.num_views, 17) and pb.dtype == np.float64
    valid = scene.gt_depth[3][scene.gt_depth[3] > 0]
    np.testing.assert_allclose(pb[3, 15:], np.percentile(valid, [0.1, 99.9]))
    np.testing.assert_array_equal(pb[:, 4], scene.height)
    np.testing.assert_array_equal(pb[:, 9], scene.width)


@pytest.mark.parametrize("fmt", FORMATS)
def test_real_format_files_only(tmp_path, scene, fmt):
    """Delete every extra of ours: the loader must still work, with None for what is missing."""
    root = write(scene, tmp_path / fmt, fmt, gt_mesh=trimesh.creation.box())
    strip_extras(root)
    assert detect_format(root) == fmt
    loaded = load_scene(root)
    assert_cameras(loaded, scene)
    np.testing.assert_array_equal(loaded.images, quantised(scene.images))
    for field in ("gt_depth", "gt_normal", "gt_instance", "seg_masks", "seg_background", "gt_mesh_path"):
        assert getattr(loaded, field) is None, field
    assert loaded.instances == {} and loaded.name == fmt
    assert loaded.kind == {"scannet": "room", "replica": "room", "dtu": "object", "llff": "forward"}[fmt]
    if fmt in ("scannet", "replica"):  # mono priors are real MonoSDF files
        np.testing.assert_array_equal(loaded.mono_depth, scene.mono_depth)
        np.testing.assert_allclose(loaded.mono_normal, scene.mono_normal, atol=1e-6)
    else:
        assert loaded.mono_depth is None and loaded.mono_normal is None
    if fmt == "llff":  # FSGS split; default scale_mat holds every camera
        np.testing.assert_array_equal(loaded.splits["test"], [0])
        np.testing.assert_array_equal(loaded.splits["train"], [1, 3, 4])  # np.round(1.5) = 2
        centres = np.linalg.inv(loaded.scale_mat) @ np.c_[scene.cam_to_world[:, :3, 3], np.ones(5)].T
        assert np.all(np.linalg.norm(centres[:3], axis=0) <= 1 + 1e-9)
    if fmt == "dtu":  # fewer than 29 views: no default sparse split
        assert loaded.splits == {}
        assert load_scene(root, train_views=[1, 3, 4]).splits["eval_only"].tolist() == [0, 2]


def test_llff_real_layout_with_jpg_and_only_downsampled(tmp_path, scene):
    """Real LLFF: images/ as JPG (sizes only checked via hwf), loading images_2 needs only that folder."""
    root = write(scene, tmp_path / "llff", "llff", factors=(2,))
    strip_extras(root)
    for p in sorted((root / "images").iterdir()):
        Image.open(p).save(p.with_suffix(".JPG"), quality=95)
        p.unlink()
    loaded = load_scene(root, factor=1)
    assert loaded.images.shape == scene.images.shape
    import shutil

    shutil.rmtree(root / "images")
    assert load_scene(root, "llff", factor=2).width == scene.width // 2


def test_scannet_real_names_not_from_zero(tmp_path, scene):
    """MonoSDF reads files in sorted order; prefixes need not be 000000.. (priors follow the rgb prefix)."""
    root = write(scene, tmp_path / "s", "scannet")
    strip_extras(root)
    for i in reversed(range(scene.num_views)):
        for suffix in ("rgb.png", "depth.npy", "normal.npy"):
            (root / f"{i:06d}_{suffix}").rename(root / f"{i + 10:06d}_{suffix}")
    loaded = load_scene(root)
    assert_cameras(loaded, scene)
    np.testing.assert_array_equal(loaded.mono_depth, scene.mono_depth)
