"""Every kind of bad input raises one BenchInputError naming the file and the problem."""

from __future__ import annotations

import re
import zipfile

import numpy as np
import pytest
from fmt_helpers import write
from PIL import Image

from bench.data.errors import BenchInputError
from bench.data.formats import detect_format, load_scene, write_scene
from bench.data.formats.npz import load_npz, save_npz


@pytest.fixture()
def scannet(tmp_path, scene):
    return write(scene, tmp_path / "scannet", "scannet")


def rewrite_npz(path, **changes):
    arrays = load_npz(path)
    for k, v in changes.items():
        if v is None:
            del arrays[k]
        else:
            arrays[k] = v
    save_npz(path, arrays)


def raises(match: str):
    return pytest.raises(BenchInputError, match=match)


# ------------------------------------------------------------------------------ cameras.npz
def test_missing_cameras(scannet):
    (scannet / "cameras.npz").unlink()
    with raises(r"cameras\.npz: file is missing"):
        load_scene(scannet, "scannet")


def test_corrupt_cameras(scannet):
    (scannet / "cameras.npz").write_bytes(b"not a zip")
    with raises(r"cameras\.npz: not a readable \.npz"):
        load_scene(scannet)


def test_missing_world_mat(scannet):
    rewrite_npz(scannet / "cameras.npz", world_mat_3=None)
    with raises(r"cameras\.npz: world_mat_3 is missing"):
        load_scene(scannet)


def test_non_invertible_world_mat(scannet):
    wm = load_npz(scannet / "cameras.npz")["world_mat_3"].copy()
    wm[1, :3] = wm[0, :3]
    rewrite_npz(scannet / "cameras.npz", world_mat_3=wm)
    with raises(r"cameras\.npz: world_mat_3 is not invertible"):
        load_scene(scannet)


def test_world_mat_wrong_shape(scannet):
    rewrite_npz(scannet / "cameras.npz", world_mat_1=np.eye(3))
    with raises(r"cameras\.npz: world_mat_1 has shape \(3, 3\)"):
        load_scene(scannet)


def test_scale_mats_differ(scannet):
    rewrite_npz(scannet / "cameras.npz", scale_mat_2=np.eye(4))
    with raises(r"cameras\.npz: scale_mat_2 differs from scale_mat_0"):
        load_scene(scannet)


# ------------------------------------------------------------------------------ priors and images
def test_nan_in_depth_prior(scannet):
    d = np.load(scannet / "000004_depth.npy")
    d[3, 3] = np.nan
    np.save(scannet / "000004_depth.npy", d)
    with raises(r"000004_depth\.npy: contains NaN"):
        load_scene(scannet)


def test_inf_in_normal_prior(scannet):
    n = np.load(scannet / "000001_normal.npy")
    n[0, 2, 2] = np.inf
    np.save(scannet / "000001_normal.npy", n)
    with raises(r"000001_normal\.npy: contains inf"):
        load_scene(scannet)


def test_nan_in_gt_depth(scannet):
    d = np.load(scannet / "000000_gt_depth.npy")
    d[0, 0] = np.nan
    np.save(scannet / "000000_gt_depth.npy", d)
    with raises(r"000000_gt_depth\.npy: contains NaN"):
        load_scene(scannet)


def test_wrong_shape_normal_prior(scannet):
    n = np.load(scannet / "000002_normal.npy")
    np.save(scannet / "000002_normal.npy", np.transpose(n, (1, 2, 0)))
    with raises(r"000002_normal\.npy: normal has shape \(24, 32, 3\), expected \(3, H, W\)"):
        load_scene(scannet)


def test_prior_size_differs_from_images(scannet):
    np.save(scannet / "000003_depth.npy", np.ones((12, 16), np.float32))
    with raises(r"000003_depth\.npy: size 16x12 \(WxH\) differs from the images' 32x24"):
        load_scene(scannet)


def test_inconsistent_image_sizes(scannet):
    Image.new("RGB", (16, 12)).save(scannet / "000002_rgb.png")
    with raises(r"000002_rgb\.png: size 16x12 \(WxH\) differs"):
        load_scene(scannet)


def test_unreadable_image(scannet):
    (scannet / "000001_rgb.png").write_bytes(b"garbage")
    with raises(r"000001_rgb\.png: not a readable image"):
        load_scene(scannet)


def test_prior_missing_for_one_view(scannet):
    (scannet / "000001_normal.npy").unlink()
    with raises(r"000001_normal\.npy: file is missing \(mono_normal exists for other views\)"):
        load_scene(scannet)


def test_malformed_json(scannet):
    (scannet / "segments.json").write_text("{not json")
    with raises(r"segments\.json: not valid JSON"):
        load_scene(scannet)


def test_meta_split_out_of_range(scannet):
    import json

    meta = json.loads((scannet / "meta.json").read_text())
    meta["splits"]["train"] = [0, 9]
    (scannet / "meta.json").write_text(json.dumps(meta))
    with raises(r"meta\.json: split 'train' has indices outside 0\.\.4"):
        load_scene(scannet)


def test_no_images(tmp_path):
    (tmp_path / "x").mkdir()
    save_npz(tmp_path / "x" / "cameras.npz", {"world_mat_0": np.eye(4)})
    with raises(r"x: no \*_rgb\.png images found"):
        load_scene(tmp_path / "x", "scannet")


# ------------------------------------------------------------------------------ format detection
def test_unknown_format(tmp_path, scannet, scene):
    with raises(r"unknown format 'colmap'"):
        load_scene(scannet, "colmap")
    (tmp_path / "empty").mkdir()
    with raises(r"empty: unknown dataset format"):
        load_scene(tmp_path / "empty")
    with raises(r"unknown format 'ply'"):
        write_scene(scene, tmp_path / "empty", "ply")
    with raises(r"nowhere: dataset folder does not exist"):
        load_scene(tmp_path / "nowhere")


def test_meta_naming_another_format_than_the_files_names_both(scannet):
    import json

    meta = json.loads((scannet / "meta.json").read_text())
    (scannet / "meta.json").write_text(json.dumps({**meta, "format": "llff"}))
    with raises(r"meta\.json: says format 'llff', but the folder's files are those of 'scannet' \(cameras\.npz \+ \*_rgb\.png\) "
                r"and not those of 'llff' \(poses_bounds\.npy\)"):
        load_scene(scannet)
    (scannet / "meta.json").write_text(json.dumps({**meta, "format": "replica"}))  # the same files: no complaint
    assert detect_format(scannet) == "replica"


def test_unknown_option(scannet):
    with raises(r"unknown option\(s\) \['factor'\] for format 'scannet'"):
        load_scene(scannet, factor=2)


# ------------------------------------------------------------------------------ writer
def test_writer_refuses_non_empty_or_missing_folder(tmp_path, scene, scannet):
    with raises(r"output folder is not empty"):
        write_scene(scene, scannet, "scannet")
    with raises(r"output folder does not exist"):
        write_scene(scene, tmp_path / "missing", "dtu")


def test_llff_writer_refuses_off_centre_K(tmp_path, scene):
    scene.intrinsics = scene.intrinsics.copy()
    scene.intrinsics[2, 0, 2] += 0.5
    (tmp_path / "l").mkdir()
    with raises(r"view 2: LLFF needs fx == fy"):
        write_scene(scene, tmp_path / "l", "llff")


def test_llff_writer_refuses_non_dividing_factor(tmp_path, scene):
    (tmp_path / "l").mkdir()
    with raises(r"factor 5 must be >= 2 and divide the image size 32x24"):
        write_scene(scene, tmp_path / "l", "llff", factors=(5,))


def test_writer_rejects_ids_beyond_16_bit(tmp_path, scene):
    scene.seg_masks = scene.seg_masks.copy()
    scene.seg_masks[1, 0, 0] = 70000
    (tmp_path / "s").mkdir()
    with raises(r"000001_seg\.png: ids must lie in 0\.\.65535"):
        write_scene(scene, tmp_path / "s", "scannet")


# ------------------------------------------------------------------------------ llff
@pytest.fixture()
def llff(tmp_path, scene):
    return write(scene, tmp_path / "llff", "llff", factors=(2,))


def test_llff_poses_bounds_wrong_shape(llff):
    np.save(llff / "poses_bounds.npy", np.zeros((5, 15)))
    with raises(r"poses_bounds\.npy: has shape \(5, 15\), expected \(N, 17\)"):
        load_scene(llff)


def test_llff_pose_not_invertible(llff):
    pb = np.load(llff / "poses_bounds.npy")
    m = pb[2, :15].reshape(3, 5)
    m[:, 1] = m[:, 0]
    pb[2, :15] = m.ravel()
    np.save(llff / "poses_bounds.npy", pb)
    with raises(r"poses_bounds\.npy: pose 2 is not invertible"):
        load_scene(llff)


def test_llff_pose_not_rotation(llff):
    pb = np.load(llff / "poses_bounds.npy")
    pb[1, 0] *= 1.5
    np.save(llff / "poses_bounds.npy", pb)
    with raises(r"poses_bounds\.npy: pose 1 rotation is not orthonormal"):
        load_scene(llff)


def test_llff_nan(llff):
    pb = np.load(llff / "poses_bounds.npy")
    pb[0, 16] = np.nan
    np.save(llff / "poses_bounds.npy", pb)
    with raises(r"poses_bounds\.npy: contains NaN or inf"):
        load_scene(llff)


def test_llff_image_count(llff):
    (llff / "images_2" / "IMG_0003.png").unlink()
    with raises(r"images_2: holds 4 images but poses_bounds\.npy has 5 poses"):
        load_scene(llff, factor=2)


def test_llff_missing_factor_folder(llff):
    with raises(r"images_8: folder is missing"):
        load_scene(llff, factor=8)


def test_llff_image_size_mismatch(llff):
    pb = np.load(llff / "poses_bounds.npy")
    pb[:, 9] = 40  # W in hwf
    np.save(llff / "poses_bounds.npy", pb)
    with raises(r"IMG_0000\.png: size 32x24 differs from 40x24 in poses_bounds\.npy"):
        load_scene(llff)


# ------------------------------------------------------------------------------ dtu
@pytest.fixture()
def dtu(tmp_path, scene):
    return write(scene, tmp_path / "dtu", "dtu")


def test_dtu_without_meta_or_images_is_unknown(dtu):
    import shutil

    shutil.rmtree(dtu / "image")
    (dtu / "meta.json").unlink()
    with raises(r"dtu: unknown dataset format"):
        detect_format(dtu)


def test_dtu_image_folder_gone(tmp_path, scene):
    import shutil

    root = write(scene, tmp_path / "d", "dtu")
    shutil.rmtree(root / "image")
    with raises(re.escape(str(root / "image")) + r": folder is missing"):
        load_scene(root, "dtu")


def test_dtu_mask_count(dtu):
    (dtu / "mask" / "002.png").unlink()
    with raises(r"mask: holds 4 masks for 5 images"):
        load_scene(dtu)


def test_dtu_mask_size(dtu):
    Image.new("L", (8, 8)).save(dtu / "mask" / "001.png")
    with raises(r"001\.png: size 8x8 \(WxH\) differs"):
        load_scene(dtu)


def test_dtu_singular_scale_mat(dtu):
    rewrite_npz(dtu / "cameras.npz", scale_mat_0=np.zeros((4, 4)))
    with raises(r"cameras\.npz: scale_mat_0 is not a similarity"):
        load_scene(dtu)


def test_zip_member_is_pickle_free(dtu):
    with zipfile.ZipFile(dtu / "cameras.npz") as zf:
        assert all(n.endswith(".npy") for n in zf.namelist())


# ------------------------------------------------------------------------------ views paired by position
def _drop_view(folder, fmt: str, i: int):
    """Remove view i's files the way a user deleting one frame would (the format's own files only)."""
    if fmt == "scannet":
        for p in folder.glob(f"{i:06d}_*"):
            p.unlink()
    else:
        (folder / "image" / f"{i:06d}.png").unlink()
        (folder / "mask" / f"{i:03d}.png").unlink()


@pytest.mark.parametrize("fmt", ["scannet", "dtu"])
def test_a_removed_view_is_not_silently_paired_with_its_neighbours_pose(tmp_path, scene, fmt):
    folder = write(scene, tmp_path / fmt, fmt)
    _drop_view(folder, fmt, 2)
    with raises(r"image number 2 is missing \(the next is 0+3[_.].*paired with cameras(_sphere)?\.npz by position"):
        load_scene(folder, fmt)


def test_more_cameras_than_images(scannet):
    arrays = load_npz(scannet / "cameras.npz")
    n = len([k for k in arrays if k.startswith("world_mat_")])
    rewrite_npz(scannet / "cameras.npz", **{f"world_mat_{n}": arrays["world_mat_0"], f"scale_mat_{n}": arrays["scale_mat_0"]})
    with raises(rf"cameras\.npz: holds {n + 1} cameras \(world_mat_\*\) for {n} images"):
        load_scene(scannet)


def test_truncated_gt_mesh(tmp_path, scene, gt_mesh):
    folder = write(scene, tmp_path / "scannet", "scannet", gt_mesh=gt_mesh)
    data = (folder / "gt_mesh.ply").read_bytes()
    (folder / "gt_mesh.ply").write_bytes(data[: len(data) // 2])
    with raises(r"gt_mesh\.ply: GT mesh cannot be read"):
        load_scene(folder)


@pytest.mark.parametrize("near, far", [(-0.5, 4.0), (3.0, 2.0), (0.0, 1.0)])
def test_llff_bounds_must_satisfy_0_lt_near_lt_far(llff, near, far):
    pb = np.load(llff / "poses_bounds.npy")
    pb[1, 15:17] = (near, far)
    np.save(llff / "poses_bounds.npy", pb)
    with raises(r"poses_bounds\.npy: bounds of view 1 are near .*need 0 < near < far"):
        load_scene(llff)
