"""The scene datasheet (bench/data/datasheet): every statistic against a hand-computed answer on small
constructed scenes, the card, its writing by ``bench scenes make`` and the ``bench scenes card`` CLI."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import trimesh

from bench.cli import main
from bench.data.datasheet import anchors_for, compute_datasheet, render_card
from bench.data.datasheet.capture import capture_stats, pair_ratios, visibility
from bench.data.datasheet.photometric import TEXTURELESS_THRESHOLD, photometric_stats
from bench.data.datasheet.priors import depth_prior_stats, normal_prior_stats
from bench.data.datasheet.regions import REGION_NAMES, compute_regions
from bench.data.datasheet.source import load_folder_with_gt
from bench.data.datasheet.thin import thin_width_stats
from bench.data.scene import InstanceInfo, Scene

WALL, BOX, BAR = 1, 2, 3


def make_test_scene(depth: np.ndarray, instance: np.ndarray, images: np.ndarray | None = None, focal: float = 50.0,
                    poses: np.ndarray | None = None, thin_ids: tuple[int, ...] = (BAR,), **fields) -> Scene:
    """A Scene of N views of (N, H, W) GT ``depth`` / ``instance`` maps: id 1 is a wall (background), every
    other id an object; grey images, pinhole K of ``focal`` px centred, cameras at the origin looking
    along +z unless ``poses`` (N, 4, 4) are given; GT normals face the camera (0, 0, -1)."""
    n, h, w = depth.shape
    K = np.array([[focal, 0.0, (w - 1) / 2], [0.0, focal, (h - 1) / 2], [0.0, 0.0, 1.0]])
    ids = sorted(int(i) for i in np.unique(instance) if i > 0)
    instances = {i: InstanceInfo(i, f"inst_{i}", "wall" if i == WALL else "chair", i == WALL, i in thin_ids) for i in ids}
    gt_normal = np.zeros((n, h, w, 3), np.float32)
    gt_normal[..., 2] = np.where(depth > 0, -1.0, 0.0)
    return Scene(name="test", kind="room", source_format="scannet",
                 images=np.full((n, h, w, 3), 0.5, np.float32) if images is None else images.astype(np.float32),
                 intrinsics=np.repeat(K[None], n, 0), cam_to_world=np.repeat(np.eye(4)[None], n, 0) if poses is None else poses,
                 scale_mat=np.eye(4), gt_depth=depth.astype(np.float32), gt_instance=instance.astype(np.int32),
                 gt_normal=gt_normal, instances=instances, **fields)


def plane(h: int = 12, w: int = 66, views: int = 1, z: float = 2.0) -> tuple[np.ndarray, np.ndarray]:
    """(depth, instance) of one wall filling every view at z-depth ``z``."""
    return np.full((views, h, w), z), np.full((views, h, w), WALL)


# ----------------------------------------------------------------------------- regions
def box_and_bar_scene() -> Scene:
    """A wall at 3 m, a 10 x 15 px box (rows 10-19, cols 5-19) and a 2 px wide bar (rows 4-27, cols 40-41) at 2 m."""
    depth, inst = plane(h=32, w=56, z=3.0)
    depth[0, 10:20, 5:20], inst[0, 10:20, 5:20] = 2.0, BOX
    depth[0, 4:28, 40:42], inst[0, 4:28, 40:42] = 2.0, BAR
    return make_test_scene(depth, inst)


def test_regions_partition_the_valid_pixels_with_thin_over_band_over_surfaces():
    r = compute_regions(box_and_bar_scene())
    parts = np.stack([getattr(r, name) for name in REGION_NAMES])
    assert (parts.sum(0) == r.valid).all()  # disjoint and covering the valid pixels
    bar = np.zeros_like(r.valid)
    bar[0, 4:28, 40:42] = True
    assert (r.thin == bar).all()  # the 5 x 5 opening removes the whole 2 px bar, nothing else
    col = 12  # a column through the box, far from the bar: the band is 2 px on each side of each edge
    assert r.planar_background[0, 7, col] and r.silhouette[0, 8, col] and r.silhouette[0, 9, col]  # wall above the box
    assert r.silhouette[0, 10, col] and r.silhouette[0, 11, col] and r.objects[0, 12, col]  # box below its top edge
    assert r.objects[0, 17, col] and r.silhouette[0, 18, col] and r.silhouette[0, 20, col] and r.planar_background[0, 22, col]
    assert r.surfaces["wall"][0, 15, 30] and not r.surfaces["wall"][0, 15, col]


def test_thin_width_of_bars_of_known_width():
    for width in (1, 2, 3, 4):
        mask = np.zeros((1, 30, 40), bool)
        mask[0, 3:27, 10:10 + width] = True
        stats = thin_width_stats(mask)
        assert stats["median_px"] == width and stats["p90_px"] == width
    depth, inst = plane(h=40, w=40)  # a 3 px leg in a scene: thin by the 5 x 5 opening, width 3
    depth[0, 5:35, 20:23], inst[0, 5:35, 20:23] = 1.5, BAR
    assert compute_datasheet(make_test_scene(depth, inst))["thin_parts"]["median_px"] == 3.0
    assert thin_width_stats(np.zeros((2, 8, 8), bool))["median_px"] is None


# ----------------------------------------------------------------------------- photometric content
def sinusoid_images(amplitude: float, period: int, h: int = 12, w: int = 66) -> np.ndarray:
    """Grey images Y = 0.5 + a sin(2 pi u / P + pi / 8): the phase keeps every gradient away from 0."""
    u = np.arange(w)
    row = 0.5 + amplitude * np.sin(2 * np.pi * u / period + np.pi / 8)
    return np.repeat(np.broadcast_to(row, (1, h, w))[..., None], 3, axis=3)


def test_gradient_energy_of_a_textured_and_a_plain_plane():
    depth, inst = plane()  # w - 2 = 64 interior columns: whole half-periods of cos^2 for P = 8
    a, period = 0.2, 8
    textured = photometric_stats(sinusoid_images(a, period), compute_regions(make_test_scene(depth, inst)))
    expected = a * a * np.sin(2 * np.pi / period) ** 2 / 2  # mean of (a sin(2 pi / P) cos(.))^2
    assert textured["gradient_energy"]["wall"] == pytest.approx(expected, rel=1e-5)
    assert textured["gradient_rms_levels"]["wall"] == pytest.approx(255 * np.sqrt(expected), rel=1e-5)
    assert textured["textureless_fraction_wall_ceiling"] == 0.0
    assert textured["gradient_energy"]["floor"] is None and textured["n_pixels"]["wall"] == 10 * 64
    plain = photometric_stats(sinusoid_images(0.0, period), compute_regions(make_test_scene(depth, inst)))
    assert plain["gradient_energy"]["wall"] == 0.0 and plain["textureless_fraction_wall_ceiling"] == 1.0


def test_sensor_noise_alone_is_not_texture():
    depth, inst = plane(h=64, w=64, views=4)
    noisy = np.clip(0.5 + np.random.default_rng(0).normal(0.0, 2 / 255, (4, 64, 64, 3)), 0, 1)  # the default sensor_noise
    stats = photometric_stats(noisy, compute_regions(make_test_scene(depth, inst)))
    assert stats["textureless_fraction_wall_ceiling"] > 0.99
    assert stats["gradient_rms_levels"]["wall"] > TEXTURELESS_THRESHOLD * 255  # unsmoothed, the noise does show


# ----------------------------------------------------------------------------- priors
def ramp_depth(views: int = 2, h: int = 16, w: int = 24) -> np.ndarray:
    return np.broadcast_to(np.linspace(1.0, 3.0, w), (views, h, w)).copy()


def test_affine_depth_prior_has_zero_error_after_alignment():
    depth = ramp_depth()
    depth[:, 2:14, 4:16] = 1.2  # a box in front: every region but thin is populated
    inst = np.where(depth == 1.2, BOX, WALL)
    scene = make_test_scene(depth, inst, mono_depth=(1.3 * depth + 0.2).astype(np.float32))
    sheet = compute_datasheet(scene)
    for region in ("all", "planar_background", "objects", "silhouette"):
        assert sheet["depth_prior"][region]["abs_rel"] == pytest.approx(0.0, abs=1e-6)
        assert sheet["depth_prior"][region]["delta1"] == 1.0
    assert sheet["depth_prior"]["thin"]["abs_rel"] is None and sheet["depth_prior"]["thin"]["n_views"] == 0


def test_depth_bias_on_one_region_stays_there():
    # Region B: GT 2.0 on half its pixels and 3.2 on the other half, the prior 2.6 on all of them (a
    # flattened step): residuals e = +0.6 / -0.6 are orthogonal to [prior, 1] over all pixels, so the
    # least-squares alignment is the identity and region A (prior = GT) keeps zero error.
    gt = ramp_depth()
    b = np.zeros(gt.shape, bool)
    b[:, 10:14, :] = True
    gt[:, 10:12, :], gt[:, 12:14, :] = 2.0, 3.2
    prior = np.where(b, 2.6, gt)
    stats = depth_prior_stats(prior, gt, {"a": ~b, "b": b, "all": np.ones_like(b)})
    assert stats["b"]["abs_rel"] == pytest.approx((0.6 / 2.0 + 0.6 / 3.2) / 2, rel=1e-9)  # 0.24375
    assert stats["b"]["delta1"] == 0.5  # 2.6 / 2.0 = 1.3 misses, 3.2 / 2.6 = 1.23 hits
    assert stats["a"]["abs_rel"] == pytest.approx(0.0, abs=1e-12) and stats["a"]["delta1"] == 1.0
    share_b = b[0].mean()
    assert stats["all"]["abs_rel"] == pytest.approx(share_b * 0.24375, rel=1e-9)
    assert stats["all"]["n_views"] == 2 and stats["b"]["n_pixels"] == b.sum()


def rotate_x(normals: np.ndarray, degrees: float) -> np.ndarray:
    t = np.radians(degrees)
    R = np.array([[1, 0, 0], [0, np.cos(t), -np.sin(t)], [0, np.sin(t), np.cos(t)]])
    return normals @ R.T


def test_normal_errors_of_known_rotations():
    gt = np.zeros((1, 20, 20, 3))
    gt[..., 2] = -1.0
    planar = np.zeros((1, 20, 20), bool)
    planar[:, :15] = True  # 300 px rotated by 10 deg
    thin = ~planar  # 100 px rotated by 40 deg
    pred = np.where(planar[..., None], rotate_x(gt, 10.0), rotate_x(gt, 40.0))
    s = normal_prior_stats(pred, gt, {"all": planar | thin, "planar": planar, "thin": thin})
    assert s["all"]["mean_deg"] == pytest.approx((300 * 10 + 100 * 40) / 400, abs=1e-6)
    assert s["all"]["median_deg"] == pytest.approx(10.0, abs=1e-6)
    assert s["all"]["within_11_25"] == s["all"]["within_22_5"] == s["all"]["within_30"] == 0.75
    assert s["planar"]["mean_deg"] == pytest.approx(10.0, abs=1e-6) and s["planar"]["within_11_25"] == 1.0
    assert s["thin"]["median_deg"] == pytest.approx(40.0, abs=1e-6) and s["thin"]["within_30"] == 0.0
    assert s["all"]["cdf"][4] == 0.0 and s["all"]["cdf"][6] == 0.75 and s["all"]["cdf"][-1] == 1.0  # at 8, 12 and 90 deg


# ----------------------------------------------------------------------------- capture
def two_camera_scene(h: int = 48, w: int = 64) -> Scene:
    """Cameras at x = 0 and x = 0.5 m looking along +z at a wall filling both images at z = 2 m (f = 50 px:
    camera 1 sees x in [-1.28, 1.28], camera 2 x in [-0.78, 1.78], both y in [-0.96, 0.96])."""
    poses = np.repeat(np.eye(4)[None], 2, 0)
    poses[1, 0, 3] = 0.5
    return make_test_scene(np.full((2, h, w), 2.0), np.full((2, h, w), WALL), poses=poses)


def test_views_per_point_and_baseline_ratio_of_two_cameras():
    scene = two_camera_scene()
    points = np.array([[-1.1, 0.0, 2.0], [0.25, 0.0, 2.0], [0.25, 0.0, 3.0], [0.25, 0.0, 1.0]])  # one / two views, behind, in front
    normals = np.tile([0.0, 0.0, -1.0], (4, 1))
    seen, facing = visibility(points, normals, scene.intrinsics, scene.cam_to_world, scene.gt_depth)
    assert seen.sum(0).tolist() == [1, 2, 0, 0] and facing.sum(0).tolist() == [1, 2, 2, 2]
    seen_back, _ = visibility(points, -normals, scene.intrinsics, scene.cam_to_world, scene.gt_depth)
    assert not seen_back.any()  # the far side of the wall faces no camera
    med, mx = pair_ratios(seen, points, scene.cam_to_world[:, :3, 3])
    assert med[1] == pytest.approx(0.5 / np.hypot(0.25, 2.0), rel=1e-12) and mx[1] == med[1]
    assert np.isnan(med[[0, 2, 3]]).all()


def test_capture_statistics_of_a_sampled_wall():
    scene = two_camera_scene()
    quad = trimesh.Trimesh(vertices=[[-1.3, -1.0, 2.0], [1.8, -1.0, 2.0], [1.8, 1.0, 2.0], [-1.3, 1.0, 2.0]], faces=[[0, 2, 1], [0, 3, 2]])
    assert quad.face_normals[0, 2] == pytest.approx(-1.0)  # faces the cameras
    stats = capture_stats(scene, quad)
    assert stats["points_source"] == "gt_mesh" and stats["n_points"] == 20000 and stats["frac_hidden"] == 0.0
    # seen by one camera: x in [-1.28, -0.78) or (1.28, 1.78], 1.0 m of the 3.06 m seen at all
    assert stats["frac_single_view"] == pytest.approx(1.0 / 3.06, abs=0.015)
    assert stats["views_per_point"]["median"] == 2 and stats["views_histogram"][0] == 0
    u, v = np.meshgrid((np.arange(64) - 31.5) / 50, (np.arange(48) - 23.5) / 50)
    assert stats["median_distance_m"] == pytest.approx(np.median(2.0 * np.sqrt(1 + u * u + v * v)), rel=1e-3)
    fallback = capture_stats(scene)  # no mesh: back-projected GT depth, all pixels of both cameras
    assert fallback["points_source"] == "gt_depth_backprojection" and fallback["n_points"] == 2 * 64 * 48
    assert fallback["frac_single_view"] == pytest.approx(12 / 64, abs=0.01)  # the 12 columns at x < -0.78 m (and mirrored)


# ----------------------------------------------------------------------------- anchors, card, CLI
def test_anchors_follow_the_profile_and_the_dataset():
    used, anchors, caveats = anchors_for("sim-metric3d-v2", "scannet")
    assert used == "sim-metric3d-v2" and anchors["normal_prior.all.mean_deg"].low == 9.9 and not caveats
    used, anchors, caveats = anchors_for(None, "replica")
    assert used == "sim-omnidata" and anchors["reference.no_prior_fscore"].low == 0.789 and len(caveats) == 2
    assert anchors_for("sim-geowizard", "dtu")[1] == {}
    for profile in ("sim-omnidata", "sim-metric3d-v2", "sim-geowizard"):
        assert all(a.cite and a.note and a.low <= a.high for a in anchors_for(profile, "scannet")[1].values())


def test_card_shows_every_section_and_its_sources():
    sheet = compute_datasheet(box_and_bar_scene())
    card = render_card(sheet)
    for title in ("Regions", "Photometric content", "Capture", "Thin parts", "Reference outcomes"):
        assert f"## {title}" in card
    assert "| property | this scene | real-data anchor | source |" in card and "no published anchor" in card
    assert sheet["depth_prior"] is None and "| AbsRel, all | n/a | 7.5 % |" in card  # no prior here: n/a beside the anchor
    assert sheet == json.loads(json.dumps(sheet))  # JSON-able as it is


@pytest.fixture(scope="module")
def tiny_folder() -> Path:
    from bench.data.datasets import ensure_dataset

    return ensure_dataset("scannet_like_tiny", "tiny")


def test_scenes_make_stores_the_datasheet_and_writes_the_card(tiny_folder):
    meta = json.loads((tiny_folder / "meta.json").read_text())
    assert meta["metadata"]["datasheet"]["scene"]["prior_profile"] == "sim-omnidata"
    assert compute_datasheet(*load_folder_with_gt(tiny_folder)) == meta["metadata"]["datasheet"]  # the folder measures alike
    assert (tiny_folder / "datasheet.md").read_text().startswith("# Datasheet: scannet_like_tiny")
    assert (tiny_folder / "datasheet.png").stat().st_size > 0


def test_cli_card_of_a_recipe_and_of_a_folder(tiny_folder, capsys, tmp_path):
    assert main(["scenes", "card", "scannet_like_tiny", "--scale", "tiny", "--out", str(tmp_path / "c.md")]) == 0
    out = capsys.readouterr().out
    assert out.startswith("# Datasheet: scannet_like_tiny") and "GeoWizard Tab. 1 (Omnidata v2)" in out
    assert (tmp_path / "c.png").is_file() and "](c.png)" in (tmp_path / "c.md").read_text()
    assert main(["scenes", "card", str(tiny_folder)]) == 0
    assert "points from gt_mesh" in capsys.readouterr().out
    assert main(["scenes", "card", str(tiny_folder), "--seed", "3"]) == 2
    assert capsys.readouterr().err.strip() == "error: --seed: applies to a recipe, not to a dataset folder"


@pytest.mark.parametrize("remove, named", [("*_gt_depth.npy", "000000_gt_depth.npy"), ("*_gt_instance.png", "000000_gt_instance.png"),
                                           ("instances.json", "instances.json")])
def test_cli_card_of_a_folder_without_gt_names_the_file(tiny_folder, tmp_path, capsys, remove, named):
    folder = tmp_path / "data"
    shutil.copytree(tiny_folder, folder)
    for p in folder.glob(remove):
        p.unlink()
    assert main(["scenes", "card", str(folder)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(folder / named) in err[0]


def test_summary_table_has_a_row_per_scene_and_the_anchor_row_of_their_profile():
    from bench.data.datasheet.card import render_summary

    def sheet(name: str, abs_rel: float) -> dict:
        return {"scene": {"name": name, "format": "scannet", "prior_profile": "sim-omnidata"},
                "depth_prior": {"all": {"abs_rel": abs_rel, "delta1": 0.95}},
                "normal_prior": {"all": {"mean_deg": 16.0, "median_deg": 9.0, "within_11_25": 0.6},
                                 "planar_background": {"mean_deg": 10.0}, "thin": {"mean_deg": 50.0}, "silhouette": {"mean_deg": 30.0}},
                "photometric": {"textureless_fraction_wall_ceiling": 0.4},
                "capture": {"views_per_point": {"median": 7.0}, "baseline_depth_ratio": {"median_of_median": 0.8}}}

    text = render_summary({"a": sheet("a", 0.07), "b": sheet("b", 0.05)})
    rows = [line for line in text.splitlines() if line.startswith("| ")]
    assert [r.split(" | ")[0] for r in rows] == ["| scene", "| a", "| b", "| real (scannet, anchors of sim-omnidata)"]
    assert "| 7.0 % | 95.0 % | 16.0 deg | 9.0 deg | 60.0 % | 10 / 50 / 30 deg | 40.0 % | 7 | 0.8 |" in rows[1]
    assert "5.0 %" in rows[2] and "[1]" in rows[3] and "\n[1] " in text
