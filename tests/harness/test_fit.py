"""`bench fit` on a dataset folder written by hand in MonoSDF's real ScanNet layout (not by the synthesiser)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh
from PIL import Image

from bench.cli import main

H, W, N = 24, 32, 4


def _hand_written_scannet_folder(root, with_gt_mesh: bool):
    """A small box room seen by 4 cameras near its centre: *_rgb.png, *_depth.npy, *_normal.npy and
    cameras.npz (world_mat_i = K4 @ world_to_cam, scale_mat_i = the normalisation), as MonoSDF's
    preprocessing writes them."""
    root.mkdir()
    rng = np.random.default_rng(0)
    K = np.array([[20.0, 0, (W - 1) / 2], [0, 20.0, (H - 1) / 2], [0, 0, 1]])
    K4 = np.eye(4)
    K4[:3, :3] = K
    scale_mat = np.diag([3.0, 3.0, 3.0, 1.0])  # normalised -> world: the room is ~6 m across
    cams = {}
    for i in range(N):
        a = 2 * np.pi * i / N
        R = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])  # yaw about y (OpenCV y down)
        c2w = np.eye(4)
        c2w[:3, :3] = R
        c2w[:3, 3] = [0.1 * np.cos(a), 0.0, 0.1 * np.sin(a)]
        cams[f"world_mat_{i}"] = K4 @ np.linalg.inv(c2w)
        cams[f"scale_mat_{i}"] = scale_mat
        Image.fromarray((rng.random((H, W, 3)) * 255).astype(np.uint8)).save(root / f"{i:06d}_rgb.png")
        np.save(root / f"{i:06d}_depth.npy", np.full((H, W), 2.0, np.float32))
        normal = np.zeros((3, H, W), np.float32)
        normal[2] = -1.0
        np.save(root / f"{i:06d}_normal.npy", normal * 0.5 + 0.5)
    np.savez(root / "cameras.npz", **cams)
    if with_gt_mesh:
        box = trimesh.creation.box(extents=(5.0, 3.0, 5.0))
        box.invert()  # seen from inside
        box.export(root / "gt_mesh.ply")
    return root


@pytest.mark.slow
def test_fit_on_a_hand_written_folder_with_and_without_gt(tmp_path, capsys):
    folder = _hand_written_scannet_folder(tmp_path / "room", with_gt_mesh=False)
    out = tmp_path / "fit"
    args = ["fit", "monosdf", str(folder), "--scale", "tiny", "--set", "iterations=6", "rays_per_batch=32", "mesh_resolution=24",
            "fractions=[0.5,1.0]", "--out", str(out)]
    assert main(args) == 0
    row = json.loads((out / "fit.json").read_text())
    assert row["format"] == "scannet" and row["iterations"] == 6 and len(row["curve"]) == 2
    assert "gt_mesh.ply is missing" in row["no_metrics"] and "No metrics" in (out / "fit.md").read_text()
    assert "mesh.ply" in row["artifacts"]["files"]

    _hand_written_scannet_folder(tmp_path / "room_gt", with_gt_mesh=True)
    out2 = tmp_path / "fit_gt"
    assert main([*args[:2], str(tmp_path / "room_gt"), *args[3:-1], str(out2)]) == 0
    row = json.loads((out2 / "fit.json").read_text())
    assert row["no_metrics"] is None and {"fscore", "acc", "comp"} <= set(row["metrics"])
    assert "Scale 'tiny' is a smoke test" in row["smoke_test"]  # metrics at tiny are not a result: every output says so
    assert "**Smoke test.**" in (out2 / "fit.md").read_text() and "[fit] Scale 'tiny' is a smoke test" in capsys.readouterr().out


def test_fit_bad_folder_is_one_clear_error(tmp_path, capsys):
    folder = _hand_written_scannet_folder(tmp_path / "room", with_gt_mesh=False)
    (folder / "000001_rgb.png").unlink()
    assert main(["fit", "monosdf", str(folder), "--scale", "tiny", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "image number 1 is missing" in err[0]
    assert not (tmp_path / "o").exists()  # nothing left behind
    assert main(["fit", "mono_sdf", str(folder), "--out", str(tmp_path / "o")]) == 2  # not a method: the known ones listed
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "'mono_sdf': not a known method (known: " in err[0] and "monosdf" in err[0]
    assert main(["fit", "monosdf", str(tmp_path / "nowhere"), "--out", str(tmp_path / "o")]) == 2
