"""Scene recipes: YAML files in ``configs/scenes/`` describing a procedural scene.

A recipe names the scene kind, the on-disk format to write, a seed, the geometry (room preset and
objects, a DTU-like object, or an LLFF-like layout), the cameras, the image size and the list of
effects to simulate. Any value may be a per-scale mapping ``{tiny: ..., small: ..., medium: ...}``;
:func:`resolve_scale` picks the entry of the requested scale.

Example (a user's own recipe with their own mesh)::

    name: my_room
    kind: room
    format: scannet
    preset: scannet
    seed: 3
    objects:
      - {type: table}
      - {type: chair, count: 2}
      - {type: mesh, path: /data/my_statue.obj, size: 0.6, category: statue, thin: false}
    effects:
      - {name: prior_profile, profile: sim-omnidata}
      - {name: segmentation_inconsistent}

Room furniture (``room:``): ``arrangement`` ``walls_and_table`` (as rooms have it) or ``scatter``
(random free spots). Room cameras (``cameras:``): ``path`` ``walk`` (a hand-held walk around the room:
``shake`` degrees, ``sweeps``, ``sweep`` degrees, ``clearance`` m) or ``loop`` (a small loop in the middle
of the room: ``loop_radius``, the loop's radii as a fraction of the room size, default 0.12), and for
both ``views`` (int >= 2), ``hfov`` (degrees), ``jitter`` (m, shakiness), ``height`` ([low, high] m).
Defaults come from the room preset (``preset:``; docs/scenes.md). Object (DTU-like) cameras: ``distance``, ``hfov``, ``train_azimuths``, ``train_elevations``,
``eval_views``; LLFF-like: ``path`` (``grid``: ``grid``, ``spacing``; ``handheld``: ``views``, ``extent``,
``rows``, ``jitter``, ``look_jitter``), ``hfov``, ``look_distance``, ``height``; the LLFF-like layout
itself under ``forward:`` (``depth_range``, ``back_wall``, ``lateral_spread``, ``wall_texture``,
``wall_texture_scale``; :func:`bench.data.synth.layouts.build_forward`).

A room's look (``look:``, :class:`LookSection`, over the preset's values): ``decor`` (none / sparse /
rich), ``wall_finish``, ``floor_finish``, ``lighting`` (directional / room) and the amounts
(``plaster_amplitude``, ``ceiling_lights``, ``light_radius``, ``window_light``, ``window_intensity``,
``ambient``, ``ao_distance``, ``ao_samples``, ``shadow_samples``); docs/scenes.md.

The sections ``room:``, ``cameras:``, ``look:`` and ``forward:`` are typed (:class:`RoomSection`, :class:`RoomCameras`,
:class:`LookSection`, :class:`ObjectCameras`, :class:`ForwardCameras`, :class:`ForwardSection`; read with
:meth:`Recipe.section`): an unknown key, a wrong type or a value out of range is one error naming the
recipe file and the key (``bench.data.config``, the harness's one config mechanism).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, Literal, TypeVar

import yaml

from bench.data.config import Range, load_config
from bench.data.errors import BenchInputError
from bench.data.scene import DATASET_FORMATS, SCENE_KINDS

SCALES = ("tiny", "small", "medium", "large")

TOP_LEVEL_KEYS = {"name", "kind", "format", "seed", "preset", "description", "room", "objects", "object", "cameras", "image", "effects", "llff", "forward",
                  "look"}
OBJECT_TYPES = ("table", "chair", "lamp", "plant", "cabinet", "sofa", "shelf", "fern", "mesh")
KIND_FORMATS = {"room": ("scannet", "replica"), "object": ("dtu",), "forward": ("llff",)}


T = TypeVar("T")
Metres = Annotated[float, Range(lo=0)]
Degrees = Annotated[float, Range(lo=0, hi=170, lo_open=True)]


# ---- typed sections of a recipe (bench.data.config: unknown keys, wrong types, out-of-range values are
# ---- errors naming the recipe and the key). None = a default that depends on the preset, scale or object.
@dataclass(frozen=True)
class RoomSection:
    """``room:`` of a room recipe: ``size`` [x, y, z] metres (None: the preset's, +-10 % from the seed);
    ``arrangement`` of the furniture (None: the preset's): ``walls_and_table`` (pieces against the walls,
    lamps and plants in corners, the table with its chairs in the free floor;
    :func:`bench.data.synth.furnish.arrange_walls_and_table`) or ``scatter`` (random free floor spots,
    away from a ``loop`` camera path); ``normalise``, the dataset's ``scale_mat``
    (:mod:`bench.data.normalisation`): ``room`` (None; the room's circumscribed sphere, 5 % over, holds the
    whole room) or ``cameras`` (MonoSDF's rule for ScanNet: the cameras' box + 1.5 m, so room corners
    further out fall outside the unit sphere)."""

    size: tuple[Annotated[float, Range(lo=1, lo_open=True)], Annotated[float, Range(lo=1, lo_open=True)],
                Annotated[float, Range(lo=1, lo_open=True)]] | None = None
    arrangement: Literal["walls_and_table", "scatter"] | None = None
    normalise: Literal["room", "cameras"] | None = None


@dataclass(frozen=True)
class LookSection:
    """``look:`` of a room recipe: finishes, wall decor and lighting (:mod:`bench.data.synth.look`).
    Every key not in the recipe takes the room preset's value (``ROOM_PRESETS[...]["look"]`` in
    :mod:`bench.data.synth.layouts`; the ``*-legacy`` presets give today's plain rooms)."""

    decor: Literal["none", "sparse", "rich"]              # bench.data.synth.decor.DECOR_LEVELS
    wall_finish: Literal["none", "plaster"]               # walls (and, at 1/3 amplitude, ceiling)
    floor_finish: Literal["tiles", "boards", "carpet"]    # tiles = the legacy floor
    lighting: Literal["directional", "room"]              # directional = legacy shading, no shadows
    plaster_amplitude: Annotated[float, Range(lo=0, hi=0.3)]  # RMS relative albedo variation of plaster
    ceiling_lights: Annotated[int, Range(lo=1, hi=16)]    # round ceiling lights on a grid
    light_radius: Annotated[float, Range(lo=0, hi=0.5)]   # m, their emitting disc (0 = point lights)
    window_light: bool                                    # each window is also an area light
    window_intensity: Annotated[float, Range(lo=0, hi=50)]  # a window's on-axis intensity / a ceiling light's
    ambient: Annotated[float, Range(lo=0, hi=5)]          # ambient / mean direct radiance over the room's faces
    ao_distance: Metres                                   # ambient-occlusion reach, m (0 = none)
    ao_samples: Annotated[int, Range(lo=0, hi=256)]       # hemisphere rays per point (0 = none)
    shadow_samples: Annotated[int, Range(lo=1, hi=256)]   # shadow rays per area light and point


@dataclass(frozen=True)
class RoomCameras:
    """``cameras:`` of a room recipe. ``path`` (None: the preset's): ``walk``, a hand-held walk around the
    room (:func:`bench.data.synth.cameras.room_walk`; keys ``shake``, ``sweeps``, ``sweep``,
    ``clearance``), or ``loop``, a small loop in the middle of the room looking across it
    (:func:`bench.data.synth.cameras.room_path`; key ``loop_radius``)."""

    path: Literal["walk", "loop"] | None = None
    views: Annotated[int, Range(lo=2)] | None = None         # None: the preset's count at the scale
    jitter: Metres | None = None                              # shakiness, m (None: the preset's); walk: std of the hand's position noise
    hfov: Degrees | None = None                               # None: the preset's
    height: tuple[Metres, Metres] | None = None               # [low, high] camera height, m (None: [1.2, 1.6] loop, [1.2, 1.7] walk)
    loop_radius: Annotated[float, Range(lo=0, hi=0.45)] = 0.12  # loop: the loop's radii / room size
    shake: Annotated[float, Range(lo=0, hi=20)] | None = None  # walk: std of roll, pitch and heading noise, degrees (None: the preset's)
    sweeps: Annotated[int, Range(lo=0, hi=100)] = 3           # walk: turns from the table group to the walls and back per loop
    sweep: Annotated[float, Range(lo=0, hi=180)] = 100.0      # walk: how far the heading turns away from the group, degrees
    clearance: Annotated[float, Range(lo=0.1, hi=1)] = 0.3    # walk: least distance from a camera to furniture and walls, m
    wall_distance: Annotated[float, Range(lo=0, hi=5)] | None = None  # walk: the path's distance from the walls, m (None: midway
                                                              # between the table group and the pieces along the walls)

    def check(self) -> str | None:
        if self.height is not None and self.height[0] > self.height[1]:
            return f"height must be [low, high] with low <= high, got {list(self.height)}"
        return None


ROOM_CAMERA_KEYS_OF_PATH = {"loop": ("loop_radius",), "walk": ("shake", "sweeps", "sweep", "clearance", "wall_distance")}


@dataclass(frozen=True)
class ObjectCameras:
    """``cameras:`` of an object (DTU-like) recipe: sparse training views + dense evaluation-only views."""

    distance: Annotated[float, Range(lo=0, lo_open=True)] | None = None  # m (None: 2.6 x the object's extent)
    hfov: Degrees = 40.0
    train_azimuths: tuple[float, ...] = (-40.0, 0.0, 40.0)    # degrees
    train_elevations: tuple[Annotated[float, Range(lo=-89, hi=89)], ...] = (30.0, 25.0, 35.0)
    eval_views: Annotated[int, Range(lo=1)] | None = None     # None: 8 / 24 / 48 / 64 by scale

    def check(self) -> str | None:
        if not self.train_azimuths:
            return "train_azimuths must list one or more angles"
        if len(self.train_elevations) != len(self.train_azimuths):
            return f"train_elevations must have one angle per azimuth ({len(self.train_azimuths)}), got {list(self.train_elevations)}"
        return None


@dataclass(frozen=True)
class ForwardCameras:
    """``cameras:`` of a forward-facing (LLFF-like) recipe: ``path: grid`` (``grid``, ``spacing``) or
    ``path: handheld`` (``views``, ``extent``, ``rows``, ``jitter``, ``look_jitter``)."""

    path: Literal["grid", "handheld"] = "grid"
    hfov: Degrees = 60.0
    look_distance: Annotated[float, Range(lo=0, lo_open=True)] = 3.0
    height: Metres = 1.0
    grid: tuple[Annotated[int, Range(lo=1)], Annotated[int, Range(lo=1)]] = (5, 4)
    spacing: tuple[Annotated[float, Range(lo=0, lo_open=True)], Annotated[float, Range(lo=0, lo_open=True)]] = (0.08, 0.06)
    views: Annotated[int, Range(lo=4, hi=1000)] = 24
    extent: tuple[Metres, Metres] = (0.6, 0.3)
    rows: Annotated[int, Range(lo=1)] = 3
    jitter: Annotated[float, Range(lo=0, hi=1)] = 0.1
    look_jitter: Annotated[float, Range(lo=0, hi=30)] = 2.0     # degrees

    def check(self) -> str | None:
        return None if self.rows <= self.views else f"rows ({self.rows}) must be <= views ({self.views})"


@dataclass(frozen=True)
class ForwardSection:
    """``forward:`` of a forward-facing recipe (:func:`bench.data.synth.layouts.build_forward`)."""

    depth_range: tuple[Annotated[float, Range(lo=0.1, hi=100)], Annotated[float, Range(lo=0.1, hi=100)]] = (1.6, 4.5)
    back_wall: Annotated[float, Range(lo=0.5, hi=100)] = 6.0
    lateral_spread: Annotated[float, Range(lo=0, hi=10)] = 0.22
    wall_texture: str = "none"
    wall_texture_scale: Annotated[float, Range(lo=0, lo_open=True)] = 0.5


@dataclass
class Recipe:
    """A parsed, validated recipe (values may still be per-scale mappings)."""

    name: str
    kind: str
    format: str
    seed: int
    raw: dict[str, Any]
    path: Path | None = None
    effects: list[dict[str, Any]] = field(default_factory=list)

    def get(self, *keys: str, default: Any = None, scale: str = "small") -> Any:
        """Nested lookup (``recipe.get("cameras", "views", scale="tiny")``) with per-scale resolution."""
        node: Any = self.raw
        for k in keys:
            if not isinstance(node, dict) or k not in node:
                return default
            node = node[k]
        return resolve_scale(node, scale, self.where(*keys))

    def section(self, cls: type[T], key: str, scale: str, defaults: dict[str, Any] | None = None) -> T:
        """The mapping at ``key`` as the typed section ``cls`` (per-scale values resolved first), over
        ``defaults`` (values for the keys the recipe does not give, e.g. a preset's)."""
        raw = self.raw.get(key)
        if raw is None:
            raw = {}
        if not isinstance(raw, dict):
            raise BenchInputError(self.where(key), f"must be a mapping, got {raw!r}")
        values = {k: resolve_scale(v, scale, self.where(key, k)) for k, v in raw.items()}
        return load_config(cls, {**(defaults or {}), **values}, self.where(key))

    def where(self, *keys: str) -> str:
        base = str(self.path) if self.path else self.name
        return f"{base} [{'.'.join(keys)}]" if keys else base


def check_number(value: Any, where: str, integer: bool = False, lo: float | None = None, hi: float | None = None,
                 lo_open: bool = False) -> float | int:
    """``value`` as an int / float within the bounds, or BenchInputError naming ``where``."""
    kind = "an integer" if integer else "a number"
    ok_type = isinstance(value, int) if integer else isinstance(value, (int, float))
    if isinstance(value, bool) or not ok_type or (not integer and not math.isfinite(value)):
        raise BenchInputError(where, f"must be {kind}, got {value!r}")
    if lo is not None and (value <= lo if lo_open else value < lo):
        raise BenchInputError(where, f"must be {'>' if lo_open else '>='} {lo:g}, got {value!r}")
    if hi is not None and value > hi:
        raise BenchInputError(where, f"must be <= {hi:g}, got {value!r}")
    return int(value) if integer else float(value)


def resolve_scale(value: Any, scale: str, where: str) -> Any:
    """Return ``value[scale]`` if ``value`` is a per-scale mapping, else ``value`` unchanged."""
    if isinstance(value, dict) and value and set(value) <= set(SCALES):
        if scale not in value:
            raise BenchInputError(where, f"no value for scale {scale!r} (has {sorted(value)})")
        return value[scale]
    return value


def parse_recipe(data: Any, where: str | Path, path: Path | None = None) -> Recipe:
    """Validate a recipe mapping; raise BenchInputError naming ``where`` and the problem."""
    if data is None or (isinstance(data, dict) and not data):
        raise BenchInputError(where, "recipe is empty")
    if not isinstance(data, dict):
        raise BenchInputError(where, f"recipe must be a mapping, got {type(data).__name__}")
    unknown = set(data) - TOP_LEVEL_KEYS
    if unknown:
        raise BenchInputError(where, f"unknown recipe keys {sorted(unknown)}; known: {sorted(TOP_LEVEL_KEYS)}")
    for key in ("name", "kind", "format"):
        if key not in data:
            raise BenchInputError(where, f"missing required key {key!r}")
    kind, fmt = data["kind"], data["format"]
    if kind not in SCENE_KINDS:
        raise BenchInputError(where, f"kind must be one of {SCENE_KINDS}, got {kind!r}")
    if fmt not in DATASET_FORMATS:
        raise BenchInputError(where, f"format must be one of {DATASET_FORMATS}, got {fmt!r}")
    if fmt not in KIND_FORMATS[kind]:
        raise BenchInputError(where, f"a {kind!r} scene is written as {KIND_FORMATS[kind]}, not {fmt!r}")
    seed = data.get("seed", 0)
    if not isinstance(seed, int) or seed < 0:
        raise BenchInputError(where, f"seed must be a non-negative integer, got {seed!r}")
    effects = data.get("effects", []) or []
    if not isinstance(effects, list) or not all(isinstance(e, dict) and "name" in e for e in effects):
        raise BenchInputError(where, "effects must be a list of mappings, each with a 'name'")
    objects = data.get("objects", []) or []
    if not isinstance(objects, list):
        raise BenchInputError(where, "objects must be a list")
    for i, obj in enumerate(objects + ([data["object"]] if "object" in data else [])):
        if not isinstance(obj, dict) or obj.get("type") not in OBJECT_TYPES:
            raise BenchInputError(where, f"object {i}: type must be one of {OBJECT_TYPES}, got {obj!r}")
        if obj["type"] == "mesh" and "path" not in obj:
            raise BenchInputError(where, f"object {i}: a 'mesh' object needs a 'path'")
    return Recipe(name=str(data["name"]), kind=kind, format=fmt, seed=seed, raw=data, path=path, effects=effects)


def load_recipe(path: str | Path) -> Recipe:
    """Read and validate a recipe YAML file."""
    path = Path(path)
    if not path.exists():
        raise BenchInputError(path, "recipe file does not exist")
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise BenchInputError(path, f"not valid YAML ({exc})") from exc
    return parse_recipe(data, path, path=path)


def with_effect_overrides(recipe: Recipe, overrides: dict[str, dict[str, Any]] | None) -> Recipe:
    """A copy of ``recipe`` whose effects named in ``overrides`` get their parameters updated, e.g.
    ``{"prior_profile": {"profile": "sim-metric3d-v2"}}`` (a table's scene variant). Raises
    BenchInputError if the recipe has no effect of a given name (nothing is silently added)."""
    if not overrides:
        return recipe
    names = [e["name"] for e in recipe.effects]
    for name, params in overrides.items():
        if name not in names:
            raise BenchInputError(recipe.where("effects"), f"no effect {name!r} to override (effects: {names})")
        if not isinstance(params, dict) or "name" in params:
            raise BenchInputError(recipe.where("effects"), f"override of {name!r} must map parameter -> value (not 'name'), got {params!r}")
    effects = [{**e, **overrides.get(e["name"], {})} for e in recipe.effects]
    return Recipe(name=recipe.name, kind=recipe.kind, format=recipe.format, seed=recipe.seed,
                  raw={**recipe.raw, "effects": effects}, path=recipe.path, effects=effects)


def resolve_mesh_path(recipe: Recipe, path: str) -> Path:
    """Mesh paths in a recipe are relative to the recipe file's folder (or absolute)."""
    p = Path(path).expanduser()
    if not p.is_absolute() and recipe.path is not None:
        p = (recipe.path.parent / p).resolve()
    return p
