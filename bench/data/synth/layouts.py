"""Scene layouts: objects + cameras + image size for the three scene kinds.

* ``room`` (ScanNet-like / Replica-like presets): a closed room with furniture that has thin parts
  (chair and table legs, a lamp pole, plant stems, shelf boards) and big planar surfaces. The furniture
  stands as rooms have it (against the walls, a table with chairs in the free floor) and the cameras walk
  around the room; no camera is inside or next to an object. The room's look (finishes, wall decor on the
  wall spans the furniture leaves free, lights; preset ``look``, recipe ``look:``) is
  :func:`bench.data.synth.look.dress_room`. The ``-legacy`` presets are the plain rooms of earlier versions
  (furniture at random spots away from a small camera loop in the middle, no decor, one directional
  light), generated exactly as they were.
* ``object`` (DTU-like): one object with thin parts on a ground plane; 3 sparse, little-overlap
  training views plus dense views used only to build the evaluation observation mask.
* ``forward`` (LLFF-like): several objects at different depths in front of a back wall; about 20
  forward-facing views on a small planar grid.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, cast

import numpy as np
import trimesh

from bench.data.errors import BenchInputError
from bench.data.normalisation import monosdf_indoor_scale_mat, sphere_scale_mat
from bench.data.synth import cameras as cams
from bench.data.synth.floorplan import Footprint
from bench.data.synth.furnish import arrange_walls_and_table
from bench.data.synth.geometry import (
    FURNITURE,
    PALETTE,
    SceneObject,
    _box,
    _jitter_colour,
    build_room_shell,
    load_user_mesh,
    place_on_floor,
)
from bench.data.synth.lighting import RoomLighting
from bench.data.synth.look import dress_room
from bench.data.synth.recipe import (
    ROOM_CAMERA_KEYS_OF_PATH,
    ForwardCameras,
    ForwardSection,
    LookSection,
    ObjectCameras,
    Recipe,
    RoomCameras,
    RoomSection,
    check_number,
    resolve_mesh_path,
)
from bench.data.synth.shading import TEXTURES

# Room looks (LookSection). Assumed values (docs/scenes.md): ScanNet rooms are plain (a door, a
# whiteboard or a picture), painted walls, carpet, one or two ceiling lights; Replica rooms are
# decorated (pictures, windows, wall shelves), wooden floors, more lights and daylight.
SCANNET_LOOK = {"decor": "sparse", "wall_finish": "plaster", "floor_finish": "carpet", "lighting": "room", "plaster_amplitude": 0.03,
                "ceiling_lights": 2, "light_radius": 0.15, "window_light": False, "window_intensity": 1.5, "ambient": 0.5,
                "ao_distance": 0.4, "ao_samples": 12, "shadow_samples": 6}
REPLICA_LOOK = {**SCANNET_LOOK, "decor": "rich", "floor_finish": "boards", "plaster_amplitude": 0.02, "ceiling_lights": 4,
                "light_radius": 0.2, "window_light": True, "ambient": 0.4, "ao_distance": 0.5}
LEGACY_LOOK = {**SCANNET_LOOK, "decor": "none", "wall_finish": "none", "floor_finish": "tiles", "lighting": "directional"}

# The room presets as scenes were first generated: a loop in the middle of the room, furniture at random
# free spots ("-legacy" presets; their scenes stay byte-identical).
_FIRST_ROOMS: dict[str, Any] = {
    "arrangement": "scatter",
    "path": "loop",
    "image": {"tiny": [64, 48], "small": [128, 96], "medium": [192, 144], "large": [384, 288]},
    "look": LEGACY_LOOK,
}
_SCANNET_LOOP: dict[str, Any] = {
    **_FIRST_ROOMS,
    "size": [4.2, 3.6, 2.6],
    "objects": [{"type": "table"}, {"type": "chair", "count": 3}, {"type": "lamp"}, {"type": "plant"}, {"type": "cabinet"}, {"type": "sofa"}],
    "jitter": 0.15,
    "hfov": 65.0,
    "views": {"tiny": 16, "small": 48, "medium": 96, "large": 200},
}
_REPLICA_LOOP: dict[str, Any] = {
    **_FIRST_ROOMS,
    "size": [5.0, 4.2, 2.8],
    "objects": [
        {"type": "table"}, {"type": "chair", "count": 4}, {"type": "lamp", "count": 2}, {"type": "plant", "count": 2},
        {"type": "shelf"}, {"type": "sofa"}, {"type": "cabinet"},
    ],
    "jitter": 0.05,
    "hfov": 70.0,
    "views": {"tiny": 16, "small": 64, "medium": 128, "large": 250},
}

# Room sizes of the walking presets (assumed): the smallest rooms that hold the preset's furniture along
# the walls and the table group with a walkway of 2 x 0.3 m around it at the -10 % size draw (the loop
# presets' 4.2 x 3.6 m and 5.0 x 4.2 m rooms do not: sofa 0.8-0.95 m deep + table group ~1.6 m + two
# walkways exceed 3.6 m). docs/scenes.md.
ROOM_PRESETS: dict[str, dict[str, Any]] = {
    # ScanNet: hand-held RGB-D sweeps of ordinary rooms: a shaky walk around the room, turning between the
    # furniture in the middle and the walls. Hand shake (assumed, no published figure): 5 cm position
    # noise, 2 deg roll / pitch / heading noise between the frames kept.
    "scannet": {**_SCANNET_LOOP, "size": [4.6, 4.3, 2.6], "arrangement": "walls_and_table", "path": "walk",
                "jitter": 0.05, "shake": 2.0, "look": SCANNET_LOOK},
    # Replica: clean reconstructions of larger, fuller rooms; smooth synthetic walks (no shake).
    "replica": {**_REPLICA_LOOP, "size": [5.4, 4.4, 2.8], "arrangement": "walls_and_table", "path": "walk",
                "jitter": 0.0, "shake": 0.0, "look": REPLICA_LOOK},
    "scannet-legacy": _SCANNET_LOOP,
    "replica-legacy": _REPLICA_LOOP,
}


@dataclass
class Layout:
    """Objects and cameras of a scene, before rendering.

    Attributes:
        objects: instances in id order (instance id = index + 1).
        K: (N, 3, 3) intrinsics; poses: (N, 4, 4) camera-to-world (OpenCV); height, width: pixels.
        scale_mat: (4, 4) normalised -> world (maps the unit sphere onto the region of interest).
        splits: view index arrays by split name.
        info: layout facts recorded in the dataset metadata.
        lighting: a room's lights, ambient occlusion and exposure (None: the legacy directional shading).
    """

    objects: list[SceneObject]
    K: np.ndarray
    poses: np.ndarray
    height: int
    width: int
    scale_mat: np.ndarray
    splits: dict[str, np.ndarray] = field(default_factory=dict)
    info: dict[str, Any] = field(default_factory=dict)
    lighting: RoomLighting | None = None


def _image_size(recipe: Recipe, scale: str, default: Any) -> tuple[int, int]:
    wh = recipe.get("image", scale=scale, default=None)
    if wh is None:
        wh = default[scale] if isinstance(default, dict) else default
    if not (isinstance(wh, (list, tuple)) and len(wh) == 2 and all(isinstance(v, int) and v >= 8 for v in wh)):
        raise BenchInputError(recipe.where("image"), f"image must be [width, height] integers >= 8, got {wh!r}")
    return int(wh[0]), int(wh[1])


def _make_object(recipe: Recipe, spec: dict[str, Any], name: str, rng: np.random.Generator) -> tuple[trimesh.Trimesh, str, bool]:
    """Build one local-frame object from a recipe entry -> (mesh, category, is_thin)."""
    kind = spec["type"]
    if kind == "mesh":
        path = resolve_mesh_path(recipe, spec["path"])
        size = check_number(spec.get("size", 0.5), recipe.where("objects", spec["type"], "size"), lo=0.0, lo_open=True)
        mesh = load_user_mesh(path, size, recipe.where("objects"))
        return mesh, str(spec.get("category", path.stem)), bool(spec.get("thin", False))
    mesh, thin = FURNITURE[kind](rng)
    if "size" in spec:  # rescale so the largest extent is `size` metres
        mesh = mesh.copy()
        size = check_number(spec["size"], recipe.where("objects", spec["type"], "size"), lo=0.0, lo_open=True)
        mesh.apply_scale(size / float(np.max(mesh.extents)))
    return mesh, kind, thin


def _expand(specs: list[dict[str, Any]], where: str) -> list[dict[str, Any]]:
    out = []
    for i, s in enumerate(specs):
        out.extend([s] * int(check_number(s.get("count", 1), f"{where} [objects.{i}.count]", integer=True, lo=1)))
    return out


def _scene_object(name: str, category: str, mesh: trimesh.Trimesh, thin: bool, rng: np.random.Generator) -> SceneObject:
    base, tex = PALETTE.get(category, PALETTE["mesh"])
    return SceneObject(name=name, category=category, mesh=mesh, is_background=False, is_thin=thin,
                       albedo=_jitter_colour(rng, base), texture=tex, texture_scale=float(rng.uniform(0.08, 0.2)))


def _room_items(recipe: Recipe, preset: dict[str, Any], rng: np.random.Generator) -> list[tuple[str, str, trimesh.Trimesh, bool]]:
    """The recipe's (or the preset's) objects as local-frame meshes, named ``<category>_<k>``, in recipe order."""
    specs = _expand(recipe.raw.get("objects") or preset["objects"], recipe.where())
    counts: dict[str, int] = {}
    items = []
    for spec in specs:
        mesh, category, thin = _make_object(recipe, spec, "", rng)
        name = f"{category}_{counts.get(category, 0)}"
        counts[category] = counts.get(category, 0) + 1
        items.append((name, category, mesh, thin))
    return items


def _room_options(recipe: Recipe, camera: RoomCameras, path: str) -> None:
    """Reject camera keys that the chosen path does not use (one error naming the key)."""
    given = set(recipe.raw.get("cameras") or {})
    for other, keys in ROOM_CAMERA_KEYS_OF_PATH.items():
        for key in keys:
            if other != path and key in given:
                raise BenchInputError(recipe.where("cameras", key), f"applies to path: {other}, not to path: {path}")


def build_room(recipe: Recipe, scale: str, rng: np.random.Generator, look_rng: np.random.Generator | None = None) -> Layout:
    """A room: shell, furniture (``room.arrangement``) and cameras (``cameras.path``) from ``rng``, its look
    (finishes, decor, lights; ``look:``) from ``look_rng`` (None: ``default_rng([recipe seed, 3])``);
    defaults from the preset. ``path: loop`` draws the cameras first and keeps the furniture off them and
    off the floor in front of doors (the order scenes were first generated in); ``path: walk`` places the
    furniture first, hangs the decor on the wall spans it leaves free and walks around it."""
    preset_name = recipe.raw.get("preset", recipe.format)
    if preset_name not in ROOM_PRESETS:
        raise BenchInputError(recipe.where("preset"), f"room preset must be one of {sorted(ROOM_PRESETS)}, got {preset_name!r}")
    preset = ROOM_PRESETS[preset_name]
    room = recipe.section(RoomSection, "room", scale)
    camera = recipe.section(RoomCameras, "cameras", scale)
    arrangement = room.arrangement or str(preset["arrangement"])
    path = camera.path or str(preset["path"])
    _room_options(recipe, camera, path)
    if (arrangement == "walls_and_table") != (path == "walk"):
        raise BenchInputError(recipe.where("cameras", "path"), f"path: {path} does not go with room.arrangement: {arrangement} "
                              "(a loop stands where walls_and_table puts the table; scatter leaves no walkway for a walk): "
                              "use walls_and_table with walk, scatter with loop")
    size: tuple[float, float, float] = room.size if room.size is not None else \
        cast(tuple[float, float, float], tuple(float(s * rng.uniform(0.9, 1.1)) for s in preset["size"]))
    n_views = camera.views if camera.views is not None else int(preset["views"][scale])
    width, height = _image_size(recipe, scale, preset["image"])
    jitter = camera.jitter if camera.jitter is not None else float(preset["jitter"])
    hfov = camera.hfov if camera.hfov is not None else float(preset["hfov"])
    height_range = camera.height if camera.height is not None else ((1.2, 1.6) if path == "loop" else (1.2, 1.7))
    if not height_range[1] < size[2]:
        raise BenchInputError(recipe.where("cameras", "height"), f"need low <= high < the room height {size[2]:g} m, got {list(height_range)}")

    clear: list[np.ndarray] = []
    if path == "loop":
        poses = cams.room_path(size, n_views, rng, height_range=height_range, jitter=jitter, radius_frac=camera.loop_radius)
        clear = [np.array([p[:2, 3] - 0.25, p[:2, 3] + 0.25]) for p in poses]

    shell = build_room_shell(size, rng)
    look = recipe.section(LookSection, "look", scale, defaults=preset["look"])
    look_rng = look_rng if look_rng is not None else np.random.default_rng([recipe.seed, 3])
    items = _room_items(recipe, preset, rng)
    group: Footprint | None = None
    roles: dict[str, str] = {}
    if arrangement == "scatter":
        dressing = dress_room(shell, size, look, look_rng)
        clear += dressing.keep_clear
        ordered = sorted(items, key=lambda it: -float(np.prod(it[2].extents[:2])))  # big footprints first
        margin = 0.15
        placed = place_on_floor(ordered, np.array([margin, margin]), np.array([size[0] - margin, size[1] - margin]), rng, keep_clear=clear)
        footprints = [Footprint.of_mesh(mesh) for _, _, mesh, _ in placed]
        dropped = sorted({n for n, *_ in items} - {n for n, *_ in placed})
    else:
        arranged = arrange_walls_and_table(items, size, rng, camera.clearance)
        placed, footprints, group, roles, dropped = arranged.placed, arranged.footprints, arranged.group, arranged.roles, arranged.dropped
        dressing = dress_room(shell, size, look, look_rng, obstacles=[mesh.bounds for _, _, mesh, _ in placed])
    objects = dressing.objects
    for name, category, mesh, thin in placed:
        objects.append(_scene_object(name, category, mesh, thin, rng))

    if path == "walk":
        shake = camera.shake if camera.shake is not None else float(preset.get("shake", 0.0))
        try:
            poses = cams.room_walk(size, n_views, rng, obstacles=footprints, around=group, min_clearance=camera.clearance,
                                   height_range=height_range, jitter=jitter, shake_deg=shake, sweeps=camera.sweeps, sweep_deg=camera.sweep,
                                   wall_distance=camera.wall_distance)
        except ValueError as exc:
            raise BenchInputError(recipe.where("cameras", "path"), f"walk: {exc}; give a larger room.size or fewer objects") from None

    K = np.repeat(cams.intrinsics(width, height, hfov)[None], n_views, axis=0)
    if room.normalise == "cameras":
        scale_mat = monosdf_indoor_scale_mat(poses)
    else:  # the room's circumscribed sphere, 5 % over
        scale_mat = sphere_scale_mat(np.array(size) / 2, 0.5 * float(np.linalg.norm(size)) * 1.05)
    info: dict[str, Any] = {"preset": preset_name, "room_size_m": list(size), "objects_not_placed": dropped, "hfov_deg": hfov, "look": dressing.info}
    if path == "walk":
        info.update({"arrangement": arrangement, "camera_path": path, "placement": roles,
                     "camera_sweeps": cams.walk_sweeps(camera.sweeps, n_views)})
    return Layout(objects, K, poses, height, width, scale_mat, splits={"train": np.arange(n_views)}, info=info,
                  lighting=dressing.lighting)


def build_object(recipe: Recipe, scale: str, rng: np.random.Generator) -> Layout:
    spec = recipe.raw.get("object") or {"type": "plant"}
    mesh, category, thin = _make_object(recipe, spec, "object", rng)
    if spec["type"] != "mesh" and "size" not in spec:
        mesh = mesh.copy()
        mesh.apply_scale(0.5 / float(np.max(mesh.extents)))
    mesh = mesh.copy()
    mesh.apply_translation([-mesh.bounds[:, 0].mean(), -mesh.bounds[:, 1].mean(), 0.0])
    obj = _scene_object(f"{category}_0", category, mesh, thin, rng)
    ground = SceneObject("ground", "ground", _box((3.0, 3.0, 0.05), (0.0, 0.0, -0.025)), is_background=True, is_thin=False,
                         albedo=_jitter_colour(rng, (0.45, 0.45, 0.5)), texture="tiles", texture_scale=0.25)
    extent = float(np.max(mesh.extents))
    centre = mesh.bounds.mean(axis=0)
    width, height = _image_size(recipe, scale, {"tiny": [64, 48], "small": [128, 96], "medium": [200, 150], "large": [400, 300]})
    camera = recipe.section(ObjectCameras, "cameras", scale)
    distance = camera.distance if camera.distance is not None else 2.6 * extent
    hfov = camera.hfov
    train_az = np.asarray(camera.train_azimuths, dtype=float)
    train_el = np.asarray(camera.train_elevations, dtype=float)
    n_eval = camera.eval_views if camera.eval_views is not None else {"tiny": 8, "small": 24, "medium": 48, "large": 64}[scale]
    eval_az = np.linspace(-90.0, 90.0, n_eval) + rng.uniform(-3, 3, n_eval)
    eval_el = rng.uniform(15.0, 60.0, n_eval)
    poses = np.concatenate([cams.sphere_views(centre, distance, train_az, train_el), cams.sphere_views(centre, distance, eval_az, eval_el)])
    n = len(poses)
    K = np.repeat(cams.intrinsics(width, height, hfov)[None], n, axis=0)
    radius = 0.5 * float(np.linalg.norm(mesh.extents)) * 1.1
    return Layout([ground, obj], K, poses, height, width, sphere_scale_mat(centre, radius),
                  splits={"train": np.arange(len(train_az)), "eval_only": np.arange(len(train_az), n)},
                  info={"object_extent_m": extent, "camera_distance_m": distance, "hfov_deg": hfov,
                        "object_bounds_m": mesh.bounds.tolist(),  # DTU protocol: evaluation box
                        "ground_plane": [0.0, 0.0, 1.0, 0.0]})     # top of the ground box: z = 0


def build_forward(recipe: Recipe, scale: str, rng: np.random.Generator) -> Layout:
    """LLFF-like forward-facing scene. Recipe keys (section ``forward:``, all optional): ``depth_range``
    ([near, far] m of the objects' centres, default [1.6, 4.5]), ``back_wall`` (distance of the back
    wall, m, default 6), ``lateral_spread`` (sideways spacing of the objects per metre of depth, default
    0.22: smaller = more overlap), ``wall_texture`` / ``wall_texture_scale`` (default none / 0.5 m); an
    object entry may fix its position with ``x`` (sideways) and ``y`` (depth), metres.
    Cameras (``cameras:``): ``path: grid`` (default; ``grid``, ``spacing``) or ``path: handheld``
    (``views``, ``extent`` [w, h] m, ``rows``, ``jitter``, ``look_jitter`` degrees; see
    :func:`bench.data.synth.cameras.handheld_forward`), ``hfov``, ``look_distance``."""
    specs = _expand(recipe.raw.get("objects") or [{"type": "plant"}, {"type": "lamp"}, {"type": "chair"}, {"type": "table"}, {"type": "cabinet"}],
                    recipe.where())
    forward = recipe.section(ForwardSection, "forward", scale)
    camera = recipe.section(ForwardCameras, "cameras", scale)
    far = forward.back_wall
    d_lo, d_hi = forward.depth_range
    if not d_lo <= d_hi < far:
        raise BenchInputError(recipe.where("forward", "depth_range"), f"need near <= far < back_wall {far:g} m, got {[d_lo, d_hi]}")
    spread = forward.lateral_spread
    wall_tex = forward.wall_texture
    if wall_tex not in TEXTURES:
        raise BenchInputError(recipe.where("forward", "wall_texture"), f"must be one of {TEXTURES}, got {wall_tex!r}")
    wall_scale = forward.wall_texture_scale
    objects = [
        SceneObject("ground", "floor", _box((8.0, far + 1, 0.05), (0.0, far / 2, -0.025)), True, False, _jitter_colour(rng, (0.5, 0.45, 0.4)), "tiles", 0.4),
        SceneObject("back_wall", "wall", _box((8.0, 0.05, 4.0), (0.0, far, 2.0)), True, False, _jitter_colour(rng, (0.75, 0.75, 0.7)), wall_tex,
                    wall_scale),
    ]
    # jitter +-0.2 m at the default 1.6-4.5 m range (2.9 m wide), proportional to the range otherwise
    depths = np.linspace(d_lo, d_hi, len(specs)) + rng.uniform(-0.2, 0.2, len(specs)) * (d_hi - d_lo) / 2.9
    counts: dict[str, int] = {}
    for i, (spec, y) in enumerate(zip(specs, depths)):
        mesh, category, thin = _make_object(recipe, spec, "", rng)
        x = (i - (len(specs) - 1) / 2) * spread * y + rng.uniform(-0.1, 0.1)
        if "x" in spec:  # an explicit position (metres; x sideways, y depth) overrides the spread
            x = float(check_number(spec["x"], recipe.where("objects", str(i), "x"), lo=-10.0, hi=10.0))
        if "y" in spec:
            y = float(check_number(spec["y"], recipe.where("objects", str(i), "y"), lo=0.1, hi=far))
        mesh = mesh.copy()
        mesh.apply_translation([x - mesh.bounds[:, 0].mean(), y - mesh.bounds[:, 1].mean(), 0.0])
        name = f"{category}_{counts.get(category, 0)}"
        counts[category] = counts.get(category, 0) + 1
        objects.append(_scene_object(name, category, mesh, thin, rng))
    width, height = _image_size(recipe, scale, {"tiny": [128, 96], "small": [256, 192], "medium": [504, 378], "large": [1008, 756]})
    hfov = camera.hfov
    look = camera.look_distance
    rig_centre = np.array([0.0, 0.0, camera.height])
    if camera.path == "grid":
        grid, spacing = camera.grid, camera.spacing
        poses = cams.forward_grid(rig_centre, grid, spacing, look_distance=look, rng=rng)
        info: dict[str, Any] = {"camera_path": "grid", "grid": list(grid), "spacing_m": list(spacing)}
    else:  # handheld
        n_views, extent, rows = camera.views, camera.extent, camera.rows
        poses = cams.handheld_forward(rig_centre, n_views, extent, look, rng, rows=rows, position_jitter=camera.jitter,
                                      look_jitter_deg=camera.look_jitter)
        info = {"camera_path": "handheld", "views": n_views, "extent_m": list(extent), "rows": rows}
    n = len(poses)
    K = np.repeat(cams.intrinsics(width, height, hfov)[None], n, axis=0)
    # LLFF protocol (FSGS): images sorted by name, test = every 8th, 3 train views evenly spaced over the rest.
    test = np.arange(0, n, 8)
    rest = np.setdiff1d(np.arange(n), test)
    train = rest[np.round(np.linspace(0, len(rest) - 1, 3)).astype(int)]
    centre = np.array([0.0, far / 2, 1.0])
    info.update(hfov_deg=hfov, object_depth_range_m=[float(d_lo), float(d_hi)], back_wall_m=far)
    return Layout(objects, K, poses, height, width, sphere_scale_mat(centre, far / 2 + 1.0),
                  splits={"train": train, "test": test}, info=info)


BUILDERS = {"room": build_room, "object": build_object, "forward": build_forward}


def build_layout(recipe: Recipe, scale: str, rng: np.random.Generator, look_rng: np.random.Generator | None = None) -> Layout:
    """Build the layout of ``recipe`` at ``scale`` from the geometry random stream ``rng`` (a room's
    look from ``look_rng``; only rooms have a look)."""
    if recipe.kind == "room":
        return build_room(recipe, scale, rng, look_rng)
    if "look" in recipe.raw:
        raise BenchInputError(recipe.where("look"), f"only room scenes have a look (this is a {recipe.kind!r} scene)")
    return BUILDERS[recipe.kind](recipe, scale, rng)
