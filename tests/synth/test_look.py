"""Rooms' look: legacy presets reproduce the plain rooms exactly; decor sits on the walls without
overlaps; lights fall off with the inverse square, cast shadows; ambient occlusion darkens corners;
the colour of a surface point does not depend on the camera; bad ``look:`` values are one clear error."""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import numpy as np
import open3d as o3d
import pytest
import yaml

from bench.data.config import load_config
from bench.data.errors import BenchInputError
from bench.data.synth import cameras as cams
from bench.data.synth.decor import DECOR_LEVELS, build_decor
from bench.data.synth.geometry import SceneObject, _box, build_room_shell
from bench.data.synth.layouts import ROOM_PRESETS
from bench.data.synth.lighting import AreaLight, PointLight, RoomLighting
from bench.data.synth.look import dress_room
from bench.data.synth.make import make_scene
from bench.data.synth.recipe import LookSection, load_recipe, parse_recipe
from bench.data.synth.render import SceneRaycaster
from bench.data.synth.shading import texture_factor

REPO = Path(__file__).resolve().parents[2]
SCENES = REPO / "configs" / "scenes"
FINGERPRINTS = Path(__file__).parent / "data" / "legacy_room_fingerprints.json"


def _raycasting_scene(objects: list[SceneObject]) -> o3d.t.geometry.RaycastingScene:
    return SceneRaycaster(objects).scene


def _look(preset: str, **overrides) -> LookSection:
    return load_config(LookSection, {**ROOM_PRESETS[preset]["look"], **overrides}, "test")


# ----------------------------------------------------------------------------- legacy presets
@pytest.mark.parametrize("name", ["scannet_like_tiny", "replica_like_0"])
def test_legacy_recipes_reproduce_the_earlier_rooms(name):
    """``configs/scenes/legacy/`` (the ``*-legacy`` presets and prior profiles) generate the rooms of the
    version before decor, room lighting, the walk and the calibrated priors: per-view means of the images
    (after effects), GT depth and prior depth to 1e-6, the instance names and pixel counts exactly, against
    a fingerprint stored with that version."""
    expected = json.loads(FINGERPRINTS.read_text())[name]
    scene, _ = make_scene(load_recipe(SCENES / "legacy" / f"{name}.yaml"), scale="tiny")
    n = scene.num_views
    np.testing.assert_allclose(scene.images.reshape(n, -1).astype(np.float64).mean(1), expected["rgb_mean"], atol=1e-6, rtol=0)
    np.testing.assert_allclose(scene.gt_depth.reshape(n, -1).astype(np.float64).mean(1), expected["depth_mean"], atol=1e-6, rtol=0)
    np.testing.assert_allclose(scene.mono_depth.reshape(n, -1).astype(np.float64).mean(1), expected["mono_depth_mean"], atol=1e-6, rtol=0)
    ids = sorted(scene.instances)
    assert [scene.instances[i].name for i in ids] == expected["instances"]
    assert [[int((scene.gt_instance[v] == i).sum()) for i in ids] for v in range(n)] == expected["instance_pixels"]


def test_legacy_look_draws_nothing_and_changes_nothing():
    size = (4.0, 3.5, 2.6)
    shell = build_room_shell(size, np.random.default_rng(0))
    rng = np.random.default_rng(5)
    state = rng.bit_generator.state
    dressing = dress_room(shell, size, _look("scannet-legacy"), rng)
    assert rng.bit_generator.state == state
    assert dressing.objects == shell and dressing.lighting is None and dressing.keep_clear == []


def test_look_does_not_move_the_cameras():
    """The look draws from its own stream: decor and lights on or off, the cameras are the same."""
    base = {**yaml.safe_load((SCENES / "scannet_like_tiny.yaml").read_text()), "preset": "scannet"}
    on, _ = make_scene(parse_recipe(base, "on"), scale="tiny")
    off, _ = make_scene(parse_recipe({**base, "look": {"decor": "none", "lighting": "directional"}}, "off"), scale="tiny")
    np.testing.assert_array_equal(on.cam_to_world, off.cam_to_world)
    assert {i.category for i in on.instances.values()} >= {"door", "skirting", "ceiling_light"}
    assert not {"door", "skirting", "ceiling_light"} & {i.category for i in off.instances.values()}


# ----------------------------------------------------------------------------- decor
def _overlap_volume(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.prod(np.clip(np.minimum(a[1], b[1]) - np.maximum(a[0], b[0]), 0.0, None)))


@pytest.mark.parametrize("level, seed", list(itertools.product(sorted(DECOR_LEVELS), range(4))))
def test_decor_hangs_on_the_walls_without_overlaps(level, seed):
    size = (4.2, 3.6, 2.6)
    decor = build_decor(size, level, np.random.default_rng(seed))
    boxes = [o.mesh.bounds for o in decor.objects]
    assert {o.category for o in decor.objects} >= {"door", "skirting", "switch"}
    for obj, b in zip(decor.objects, boxes):
        assert np.all(b[0] >= -1e-9) and np.all(b[1] <= np.array(size) + 1e-9), obj.name  # inside the room
        gaps = [b[0, 0], size[0] - b[1, 0], b[0, 1], size[1] - b[1, 1]]  # to the walls x=0, x=sx, y=0, y=sy
        depths = [(b[1] - b[0])[w // 2] for w in range(4) if gaps[w] < 1e-9]  # how far it stands out of each wall it touches
        assert depths, f"{obj.name} does not touch a wall"
        assert min(depths) <= (0.2 if obj.category == "wall_shelf" else 0.08) + 1e-9, f"{obj.name} stands {min(depths):.3f} m proud"
        assert obj.is_background == (obj.category in ("skirting", "switch", "socket")), obj.name
    parts = [[c.bounds for c in o.mesh.split(only_watertight=False)] for o in decor.objects]  # the boxes of each item
    for i, j in itertools.combinations(range(len(parts)), 2):
        worst = max(_overlap_volume(a, b) for a in parts[i] for b in parts[j])
        assert worst < 1e-12, f"{decor.objects[i].name} overlaps {decor.objects[j].name}"
    doors = [o for o in decor.objects if o.category == "door"]
    assert len(decor.keep_clear) >= len(doors)
    for door in doors:  # a keep-clear box on the floor right in front of each door
        fp = door.mesh.bounds[:, :2]
        assert any(np.all(k[0] <= fp[1] + 1e-9) and np.all(fp[0] <= k[1] + 1e-9) and np.max(k[1] - k[0]) >= 0.8 for k in decor.keep_clear)


def test_plaster_keeps_walls_nearly_plain():
    """``plaster_amplitude`` is the RMS of the relative albedo variation: walls stay within a few %."""
    g = np.linspace(0.0, 4.0, 200)
    pts = np.stack(np.meshgrid(g, [0.0], g, indexing="ij"), axis=-1).reshape(-1, 3)
    f = texture_factor("plaster", pts, 0.8, 1.0, amplitude=0.03)
    assert 0.02 < f.std() < 0.04 and abs(f.mean() - 1.0) < 0.01 and np.abs(f - 1).max() < 0.15
    with pytest.raises(ValueError, match="fixed amplitude"):
        texture_factor("wood", pts, 0.8, 1.0, amplitude=0.03)


# ----------------------------------------------------------------------------- lighting
def _floor() -> SceneObject:
    return SceneObject("floor", "floor", _box((10.0, 10.0, 0.1), (0.0, 0.0, -0.05)), True, False, np.array([0.6, 0.6, 0.6]))


def test_point_light_falls_off_with_the_inverse_square():
    """A floor point under a point light at (0.5, -0.3, 2.0): value = exposure rho / pi I cos(theta) / r^2,
    computed by hand; through the renderer too (the centre pixel of a camera looking at the point)."""
    light = PointLight(np.array([0.5, -0.3, 2.0]), np.array([3.0, 2.0, 1.0]))
    lighting = RoomLighting((light,), ambient=np.zeros(3), ao_distance=0.0, ao_samples=0, exposure=1.5)
    p = np.array([[0.2, 0.4, 0.0]])
    r = light.position - p[0]
    expected = 1.5 * 0.6 / np.pi * light.intensity * (r[2] / np.linalg.norm(r)) / (r @ r)
    scene = _raycasting_scene([_floor()])
    np.testing.assert_allclose(lighting.shade(scene, p, np.array([[0.0, 0.0, 1.0]]), np.full((1, 3), 0.6))[0], expected, rtol=1e-12)
    rc = SceneRaycaster([_floor()], lighting=lighting)
    K = cams.intrinsics(21, 15, 40.0)
    rgb, depth, *_ = rc.render(K, cams.look_at(np.array([1.5, 1.0, 1.2]), p[0]), 15, 21)
    np.testing.assert_allclose(rgb[7, 10], expected, rtol=1e-4)  # the hit point is p up to float32 rounding


def test_an_occluded_point_is_in_shadow():
    blocker = SceneObject("box", "cabinet", _box((0.4, 0.4, 0.4), (0.0, 0.0, 1.0)), False, False, np.array([0.5, 0.5, 0.5]))
    scene = _raycasting_scene([_floor(), blocker])
    for light in (PointLight(np.array([0.0, 0.0, 2.5]), np.ones(3)),
                  AreaLight(np.array([0.0, 0.0, 2.5]), np.array([0.0, 0.0, -1.0]), np.array([1.0, 0.0, 0.0]), np.ones(3), samples=8, radius=0.1)):
        lighting = RoomLighting((light,), np.zeros(3), 0.0, 0, 1.0)
        pts, up = np.array([[0.0, 0.0, 0.0], [1.5, 0.0, 0.0]]), np.tile([0.0, 0.0, 1.0], (2, 1))
        e = lighting.irradiance(scene, pts, up)
        assert np.all(e[0] == 0.0) and np.all(e[1] > 0.0)  # under the box: shadow; beside it: lit
        assert np.all(lighting.irradiance(None, pts, up)[0] > e[1])  # without the scene: no shadow (and closer)


def test_area_light_soft_shadow_is_partial_in_the_penumbra():
    """A 20 cm box halfway under a disc light of radius 30 cm: the floor point straight below sees the
    box hide the middle of the disc (a 40 cm square of it): partly lit, a soft shadow; under a point
    light at the disc's centre it is fully dark."""
    blocker = SceneObject("box", "cabinet", _box((0.2, 0.2, 0.05), (0.0, 0.0, 1.0)), False, False, np.array([0.5, 0.5, 0.5]))
    scene = _raycasting_scene([_floor(), blocker])
    centre, down = np.array([0.0, 0.0, 2.0]), np.array([0.0, 0.0, -1.0])
    disc = RoomLighting((AreaLight(centre, down, np.array([1.0, 0.0, 0.0]), np.ones(3), samples=32, radius=0.3),), np.zeros(3), 0.0, 0, 1.0)
    point = RoomLighting((PointLight(centre, np.ones(3)),), np.zeros(3), 0.0, 0, 1.0)
    pts, up = np.array([[0.0, 0.0, 0.0]]), np.array([[0.0, 0.0, 1.0]])
    shadowed, open_ = disc.irradiance(scene, pts, up)[0, 0], disc.irradiance(None, pts, up)[0, 0]
    assert 0.2 * open_ < shadowed < 0.8 * open_
    assert point.irradiance(scene, pts, up)[0, 0] == 0.0


def test_ambient_occlusion_darkens_a_corner():
    size = (4.0, 3.0, 2.5)
    scene = _raycasting_scene(build_room_shell(size, np.random.default_rng(0)))
    lighting = RoomLighting((), np.ones(3), ao_distance=0.5, ao_samples=32, exposure=1.0)
    corner = np.array([[0.03, 0.03, 0.0]])  # on the floor, 3 cm from two walls
    middle = np.array([[0.0, 1.5, 1.25]])   # the middle of the west wall
    ao_corner = lighting.ambient_occlusion(scene, corner, np.array([[0.0, 0.0, 1.0]]))[0]
    ao_middle = lighting.ambient_occlusion(scene, middle, np.array([[1.0, 0.0, 0.0]]))[0]
    assert ao_middle == pytest.approx(1.0) and ao_corner < 0.6


def test_a_surface_point_has_the_same_colour_from_two_cameras():
    """View independence: a dressed room (Replica look: decor, 4 ceiling lights, a window light, AO,
    soft shadows) with a table. Camera A looks into a corner; every 3rd pixel's surface point is
    rendered again at the centre pixel of a camera B looking at it from elsewhere (the centre pixel's
    ray is the optical axis). Where B sees the same point, the colours agree to 2e-4 (0.05 / 255): the
    two hit points differ by float32 rounding (~1e-6 m) only."""
    size = (4.6, 3.8, 2.7)
    dressing = dress_room(build_room_shell(size, np.random.default_rng(1)), size, _look("replica"), np.random.default_rng(2))
    table = SceneObject("table_0", "table", _box((1.0, 0.7, 0.04), (3.4, 2.8, 0.74)), False, False, np.array([0.55, 0.38, 0.22]), "wood", 0.1)
    rc = SceneRaycaster([*dressing.objects, table], seed=3, lighting=dressing.lighting)
    eye_a, eye_b = np.array([1.5, 1.2, 1.5]), np.array([2.6, 0.8, 1.1])
    pose_a = cams.look_at(eye_a, np.array([size[0], size[1], 0.4]))
    K_a = cams.intrinsics(32, 24, 70.0)
    rgb_a, depth_a, _, _ = rc.render(K_a, pose_a, 24, 32)
    K_b = cams.intrinsics(21, 15, 30.0)
    points, colours_a, colours_b = [], [], []
    for v, u in itertools.product(range(1, 24, 3), range(1, 32, 3)):
        ray = np.linalg.inv(K_a) @ np.array([u, v, 1.0])
        p = eye_a + pose_a[:3, :3] @ ray * depth_a[v, u]
        pose_b = cams.look_at(eye_b, p)
        rgb_b, depth_b, _, _ = rc.render(K_b, pose_b, 15, 21)
        if np.linalg.norm(eye_b + pose_b[:3, 2] * depth_b[7, 10] - p) > 1e-4:
            continue  # hidden from B
        points.append(p)
        colours_a.append(rgb_a[v, u])
        colours_b.append(rgb_b[7, 10])
    np.testing.assert_allclose(np.array(colours_a), np.array(colours_b), atol=2e-4, rtol=0)
    points = np.array(points)
    assert len(points) >= 40
    lighting = dressing.lighting
    normals = np.tile([0.0, 0.0, 1.0], (len(points), 1))
    on_floor = points[:, 2] < 1e-4
    ao = lighting.ambient_occlusion(rc.scene, points[on_floor], normals[on_floor])
    lit = lighting.irradiance(rc.scene, points[on_floor], normals[on_floor]) / lighting.irradiance(None, points[on_floor], normals[on_floor])
    assert ao.min() < 0.8 and lit.min() < 0.5  # compared points include a darkened corner and a (soft) shadow


# ----------------------------------------------------------------------------- recipes
@pytest.mark.parametrize("look, match", [
    ({"decor": "lots"}, r"\[look\]: config key 'decor'"),
    ({"ao_samples": -1}, r"\[look\]: config key 'ao_samples'"),
    ({"ceiling_lights": 2.5}, r"\[look\]: config key 'ceiling_lights'"),
    ({"lihgting": "room"}, r"\[look\]: unknown config key 'lihgting'"),
    ("bright", r"\[look\]: must be a mapping"),
])
def test_bad_look_values_name_the_key(tmp_path, look, match):
    path = tmp_path / "r.yaml"
    path.write_text(yaml.safe_dump({"name": "v", "kind": "room", "format": "scannet", "preset": "scannet",
                                    "objects": [{"type": "table"}], "look": look}))
    with pytest.raises(BenchInputError, match=match) as err:
        make_scene(load_recipe(path), scale="tiny")
    assert str(path) in str(err.value)


def test_a_look_outside_a_room_is_an_error(tmp_path):
    path = tmp_path / "o.yaml"
    path.write_text(yaml.safe_dump({"name": "o", "kind": "object", "format": "dtu", "look": {"decor": "rich"}}))
    with pytest.raises(BenchInputError, match=r"\[look\]: only room scenes have a look"):
        make_scene(load_recipe(path), scale="tiny")
