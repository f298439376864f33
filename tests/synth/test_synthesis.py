"""Scene synthesis: rendering conventions, recipes, determinism, bad input, atomic output."""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pytest
import trimesh
import yaml

from bench.data.errors import BenchInputError
from bench.data.synth import cameras as cams
from bench.data.synth.geometry import FURNITURE, SceneObject, _box
from bench.data.synth.layouts import build_layout
from bench.data.synth.make import make_dataset, make_scene
from bench.data.synth.recipe import load_recipe, parse_recipe
from bench.data.synth.render import SceneRaycaster
from metrics.camera import backproject

REPO = Path(__file__).resolve().parents[2]
SCENES = REPO / "configs" / "scenes"
MESHES = REPO.parent / "shared" / "assets" / "meshes"


def _tree_digest(folder: Path) -> dict[str, str]:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.rglob("*")) if p.is_file()}


def _distance_to_mesh(mesh: trimesh.Trimesh, points: np.ndarray) -> np.ndarray:
    import open3d as o3d

    rs = o3d.t.geometry.RaycastingScene()
    rs.add_triangles(o3d.core.Tensor(mesh.vertices.astype(np.float32)), o3d.core.Tensor(mesh.faces.astype(np.uint32)))
    return rs.compute_distance(o3d.core.Tensor(points.astype(np.float32))).numpy()


def _write_recipe(tmp_path: Path, data: dict, name: str = "r.yaml") -> Path:
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data))
    return path


# ----------------------------------------------------------------------------- rendering conventions
def test_raycaster_returns_z_depth_and_camera_frame_normals():
    """A camera looking at a wall 2 m away, slightly rotated: every pixel's z-depth of the wall plane
    must match the analytic value, and the normal (camera frame) must face the camera."""
    wall = SceneObject("wall", "wall", _box((20.0, 0.1, 20.0), (0.0, 2.05, 0.0)), True, False, np.array([0.5, 0.5, 0.5]))
    rc = SceneRaycaster([wall])
    K = cams.intrinsics(64, 48, 60.0)
    pose = cams.look_at(np.array([0.0, 0.0, 0.0]), np.array([0.3, 2.0, 0.2]))
    rgb, depth, normal, inst = rc.render(K, pose, 48, 64)
    assert np.all(inst == 1) and np.all(depth > 0)
    pts = backproject(depth.astype(np.float64), K, pose)
    np.testing.assert_allclose(pts[..., 1], 2.0, atol=1e-4)  # every back-projected point lies on the wall plane y = 2
    n_world = normal.reshape(-1, 3) @ pose[:3, :3].T
    np.testing.assert_allclose(n_world, np.tile([0.0, -1.0, 0.0], (48 * 64, 1)), atol=1e-5)
    assert np.all((rgb >= 0) & (rgb <= 1))


def test_look_at_is_opencv():
    pose = cams.look_at(np.array([0.0, 0.0, 1.0]), np.array([0.0, 5.0, 1.0]))
    np.testing.assert_allclose(pose[:3, 2], [0, 1, 0], atol=1e-12)  # forward = +z camera
    np.testing.assert_allclose(pose[:3, 1], [0, 0, -1], atol=1e-12)  # image down = world down
    np.testing.assert_allclose(pose[:3, 0], [1, 0, 0], atol=1e-12)  # right
    assert np.isclose(np.linalg.det(pose[:3, :3]), 1.0)


# ----------------------------------------------------------------------------- recipes
@pytest.mark.parametrize("name", ["scannet_like_tiny", "replica_like_0", "dtu_like_0", "llff_like_0"])
def test_shipped_recipes_render_sensible_scenes(name):
    scene, mesh = make_scene(load_recipe(SCENES / f"{name}.yaml"), scale="tiny")
    scene.validate()
    assert scene.num_views >= 3
    assert len(mesh.faces) > 0
    hit = scene.gt_depth > 0
    assert hit.mean() > 0.8
    # GT depth back-projects onto the GT mesh (z-depth convention end to end)
    v = 0
    pts = backproject(scene.gt_depth[v].astype(np.float64), scene.intrinsics[v], scene.cam_to_world[v])[hit[v]]
    sub = pts[:: max(1, len(pts) // 500)]
    dist = _distance_to_mesh(mesh, sub)
    assert np.percentile(dist, 99) < 5e-3
    # instance table: background flags on walls/floor, thin flags on furniture with legs/poles/stems
    cats = {i.category: i for i in scene.instances.values()}
    if scene.kind == "room":
        assert cats["wall"].is_background and cats["floor"].is_background
        assert any(i.is_thin for i in scene.instances.values() if not i.is_background)
    for v in range(scene.num_views):
        assert set(np.unique(scene.gt_instance[v])) - {0} <= set(scene.instances)


def test_room_cameras_are_outside_furniture():
    scene, mesh = make_scene(load_recipe(SCENES / "scannet_like_0.yaml"), scale="small")
    assert scene.num_views == 48 and (scene.width, scene.height) == (128, 96)
    assert scene.gt_depth[scene.gt_depth > 0].min() > 0.3  # nothing right in front of the lens


def test_room_furniture_is_placed_and_leaves_doors_clear():
    """The plain (legacy) room places all its furniture; with decor, no furniture stands on the floor
    in front of a door (what could not be placed elsewhere is recorded as not placed)."""
    data = yaml.safe_load((SCENES / "scannet_like_0.yaml").read_text())
    legacy = build_layout(parse_recipe({**data, "preset": "scannet-legacy"}, "legacy"), "small", np.random.default_rng([0, 0]))
    assert not legacy.info["objects_not_placed"]
    layout = build_layout(parse_recipe(data, "decor"), "small", np.random.default_rng([0, 0]), np.random.default_rng([0, 3]))
    room = np.array(layout.info["room_size_m"][:2])
    fronts = []
    for door in (o.mesh.bounds[:, :2] for o in layout.objects if o.category == "door"):
        front = door.copy()  # the door's width, 0.85 m into the room from its wall
        ax = int(np.argmin(door[1] - door[0]))
        front[:, ax] = [0.0, 0.85] if door[0, ax] < 1e-9 else [room[ax] - 0.85, room[ax]]
        fronts.append(front)
    assert fronts
    for obj in (o for o in layout.objects if o.category in FURNITURE):
        fp = obj.mesh.bounds[:, :2]
        assert not any(np.all(fp[0] < f[1]) and np.all(f[0] < fp[1]) for f in fronts), f"{obj.name} blocks a door"


def test_no_prior_error_effects_give_exact_priors(tmp_path):
    path = _write_recipe(tmp_path, {"name": "exact", "kind": "room", "format": "scannet", "preset": "scannet", "seed": 3,
                                    "objects": [{"type": "table"}, {"type": "lamp"}], "effects": [{"name": "sensor_noise"}]})
    scene, _ = make_scene(load_recipe(path), scale="tiny")
    np.testing.assert_array_equal(scene.mono_depth, scene.gt_depth)
    np.testing.assert_array_equal(scene.mono_normal, scene.gt_normal)


def test_effects_are_recorded_in_metadata():
    scene, _ = make_scene(load_recipe(SCENES / "scannet_like_tiny.yaml"), scale="tiny")
    names = [r["name"] for r in scene.metadata["effects"]]
    assert "prior_profile" in names and "segmentation_inconsistent" in names
    assert not np.array_equal(scene.mono_depth, scene.gt_depth)


def test_user_mesh_object(tmp_path):
    mesh_path = tmp_path / "thing.obj"
    trimesh.creation.torus(0.3, 0.05).export(mesh_path)
    path = _write_recipe(tmp_path, {"name": "user", "kind": "object", "format": "dtu", "seed": 1,
                                    "object": {"type": "mesh", "path": "thing.obj", "size": 0.4, "category": "torus"}})
    scene, mesh = make_scene(load_recipe(path), scale="tiny")
    assert any(i.category == "torus" for i in scene.instances.values())
    assert len(scene.view_indices("train")) == 3 and len(scene.view_indices("eval_only")) > 0


@pytest.mark.skipif(not (MESHES / "bunny.ply").exists(), reason="shared real meshes not present")
def test_real_bunny_recipe():
    scene, mesh = make_scene(load_recipe(SCENES / "dtu_bunny.yaml"), scale="tiny")
    obj = [i for i in scene.instances.values() if i.category == "bunny"]
    assert obj and np.any(scene.gt_instance == obj[0].instance_id)


@pytest.mark.skipif(not (MESHES / "chair_model.obj").exists(), reason="shared real meshes not present")
def test_real_lampshade_recipe_is_thin():
    scene, mesh = make_scene(load_recipe(SCENES / "dtu_lampshade.yaml"), scale="tiny")
    obj = [i for i in scene.instances.values() if i.category == "lampshade"]
    assert obj and obj[0].is_thin and np.any(scene.gt_instance == obj[0].instance_id)


def test_handheld_forward_scene_has_foliage_parallax_and_the_llff_split():
    """The Table 3 scenes: a hand-held sweep (positions spread over the recipe's extent, in capture order),
    fern foliage in view, and test views (every 8th) between training views."""
    recipe = load_recipe(SCENES / "llff_handheld_0.yaml")
    scene, _ = make_scene(recipe, scale="small")
    centres = scene.cam_to_world[:, :3, 3]
    assert scene.num_views == 24
    assert 0.4 < np.ptp(centres[:, 0]) < 0.7 and 0.15 < np.ptp(centres[:, 2]) < 0.4  # extent [0.5, 0.25] m + jitter
    assert scene.view_indices("test").tolist() == [0, 8, 16]
    train = scene.view_indices("train")
    assert len(train) == 3 and not set(train) & {0, 8, 16}
    fern = [i for i in scene.instances.values() if i.category == "fern"]
    assert fern and fern[0].is_thin
    frac = np.mean(scene.gt_instance == fern[0].instance_id)
    assert 0.03 < frac < 0.6  # in view, not filling it
    # finely textured back wall (grain): its colour varies on a flat wall
    wall = [i for i in scene.instances.values() if i.category == "wall"][0]
    px = scene.images[0][scene.gt_instance[0] == wall.instance_id]
    assert px.std(0).mean() > 0.02


def test_forward_layout_keys_are_checked(tmp_path):
    base = {"name": "fwd", "kind": "forward", "format": "llff", "seed": 1, "llff": {"factors": [2]}}
    for extra, match in [({"forward": {"depth_range": [3.0, 1.0]}}, "depth_range"),
                         ({"forward": {"wall_texture": "marble"}}, "wall_texture"),
                         ({"cameras": {"path": "orbit"}}, "path"),
                         ({"cameras": {"path": "handheld", "views": 2}}, "views")]:
        path = _write_recipe(tmp_path, {**base, **extra})
        with pytest.raises(BenchInputError, match=match):
            make_scene(load_recipe(path), scale="tiny")


# ----------------------------------------------------------------------------- determinism and atomic output
def test_same_recipe_and_seed_give_identical_bytes(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    make_dataset(SCENES / "scannet_like_tiny.yaml", a, scale="tiny")
    make_dataset(SCENES / "scannet_like_tiny.yaml", b, scale="tiny")
    da, db = _tree_digest(a), _tree_digest(b)
    assert da == db and len(da) > 20


def test_different_seed_gives_different_scene(tmp_path):
    s0, _ = make_scene(load_recipe(SCENES / "scannet_like_tiny.yaml"), scale="tiny", seed=0)
    s1, _ = make_scene(load_recipe(SCENES / "scannet_like_tiny.yaml"), scale="tiny", seed=1)
    assert not np.array_equal(s0.cam_to_world, s1.cam_to_world)


@pytest.mark.parametrize(
    "data, match",
    [
        ({}, "empty"),
        ({"name": "x", "kind": "room"}, "missing required key 'format'"),
        ({"name": "x", "kind": "cave", "format": "scannet"}, "kind must be one of"),
        ({"name": "x", "kind": "room", "format": "llff"}, "written as"),
        ({"name": "x", "kind": "room", "format": "scannet", "colour": 1}, "unknown recipe keys"),
        ({"name": "x", "kind": "room", "format": "scannet", "objects": [{"type": "piano"}]}, "type must be one of"),
        ({"name": "x", "kind": "room", "format": "scannet", "seed": -1}, "seed"),
    ],
)
def test_bad_recipes_raise_one_clear_error(tmp_path, data, match):
    path = _write_recipe(tmp_path, data)
    with pytest.raises(BenchInputError, match=match) as err:
        load_recipe(path)
    assert str(path) in str(err.value)


@pytest.mark.parametrize(
    "effects, match",
    [
        ([{"name": "no_such_effect"}], "no_such_effect"),
        ([{"name": "sensor_noise", "sigma": -3.0}], "sigma"),
        ([{"name": "sensor_noise", "volume": 2}], "volume"),
    ],
)
def test_bad_effects_fail_and_leave_nothing_behind(tmp_path, effects, match):
    path = _write_recipe(tmp_path, {"name": "bad", "kind": "room", "format": "scannet", "preset": "scannet",
                                    "objects": [{"type": "table"}], "effects": effects})
    out = tmp_path / "out"
    with pytest.raises(BenchInputError, match=match):
        make_dataset(path, out, scale="tiny")
    assert not out.exists()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def test_missing_user_mesh_is_a_clear_error(tmp_path):
    path = _write_recipe(tmp_path, {"name": "m", "kind": "object", "format": "dtu", "object": {"type": "mesh", "path": "nope.ply"}})
    with pytest.raises(BenchInputError, match="nope.ply"):
        make_scene(load_recipe(path), scale="tiny")


def test_per_scale_values_need_the_requested_scale():
    r = parse_recipe({"name": "x", "kind": "room", "format": "scannet", "image": {"small": [128, 96]}}, "mem")
    with pytest.raises(BenchInputError, match="no value for scale 'tiny'"):
        make_scene(r, scale="tiny")


@pytest.mark.parametrize(
    "patch, match",
    [
        ({"objects": [{"type": "chair", "count": "two"}]}, r"objects\.0\.count\]: must be an integer, got 'two'"),
        ({"objects": [{"type": "chair", "count": -2}]}, r"objects\.0\.count\]: must be >= 1, got -2"),
        ({"objects": [{"type": "chair", "size": 0}]}, r"objects\.chair\.size\]: must be > 0, got 0"),
        ({"objects": [{"type": "chair", "size": "big"}]}, r"objects\.chair\.size\]: must be a number"),
        ({"cameras": {"views": "many"}}, r"\[cameras\]: config key 'views' must be an integer in \[2, inf\) or null \(got 'many'\)"),
        ({"cameras": {"hfov": -30}}, r"\[cameras\]: config key 'hfov' must be a number in \(0, 170\] or null \(got -30\)"),
        ({"cameras": {"jitter": "lots"}}, r"\[cameras\]: config key 'jitter' must be a number"),
        ({"cameras": {"height": [1.6, 1.2]}}, r"\[cameras\]: RoomCameras: height must be \[low, high\] with low <= high"),
        ({"cameras": {"height": [1.2, 2.9]}}, r"cameras\.height\]: need low <= high < the room height"),
        ({"cameras": {"veiws": 20}}, r"\[cameras\]: unknown config key 'veiws' of RoomCameras"),  # a typo was silently ignored
        ({"room": {"size": [4.0, 3.0]}}, r"\[room\]: config key 'size' must be a list"),
    ],
)
def test_bad_recipe_values_name_the_key(tmp_path, patch, match):
    """Bad values and unknown keys of a recipe's sections are one-line errors naming the recipe file and
    the key (typed sections, bench.data.config; they were tracebacks or silently accepted)."""
    path = _write_recipe(tmp_path, {"name": "v", "kind": "room", "format": "scannet", "preset": "scannet",
                                    "objects": [{"type": "table"}], **patch})
    with pytest.raises(BenchInputError, match=match) as err:
        make_scene(load_recipe(path), scale="tiny")
    assert str(path) in str(err.value)


def test_negative_seed_override_is_a_clear_error():
    with pytest.raises(BenchInputError, match="--seed: must be a non-negative integer, got -1"):
        make_scene(load_recipe(SCENES / "scannet_like_tiny.yaml"), scale="tiny", seed=-1)
