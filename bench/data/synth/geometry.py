"""Procedural scene geometry: rooms, furniture with thin parts, DTU-like objects, LLFF-like layouts.

Every builder returns :class:`SceneObject` values: a trimesh mesh in world metres (z up, floor at z = 0)
plus what the renderer and the effects need to know about it (category, background flag, thin flag,
texture). Everything is deterministic given the numpy Generator passed in.

Thin parts are real geometry at realistic sizes (chair legs 2-3 cm across, a lamp pole ~2.4 cm, plant
stems ~1.6 cm): at 128 x 96 pixels they cover 1-3 pixels, which is exactly where monocular depth
networks fail and where MonoInstance's uncertainty is meant to help.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import cast

import numpy as np
import trimesh

from bench.data.errors import BenchInputError
from bench.data.synth.materials import Material

BACKGROUND_CATEGORIES = ("wall", "floor", "ceiling", "ground")


@dataclass
class SceneObject:
    """One instance of a synthetic scene.

    Attributes:
        name: unique readable name (``"chair_0"``).
        category: class name (``"chair"``, ``"wall"`` ...).
        mesh: triangle mesh in world metres.
        is_background: wall / floor / ceiling / ground plane.
        is_thin: has thin parts (legs, poles, stems, wires).
        albedo: (3,) base RGB in [0, 1].
        texture: procedural texture name, see ``bench.data.synth.shading.TEXTURES`` ("none" = textureless).
        texture_scale: spatial period of the texture in metres.
        material: albedo as a function of the world point (:mod:`bench.data.synth.materials`); when
            set it replaces ``albedo`` x ``texture`` (room finishes and wall decor; None = legacy).
    """

    name: str
    category: str
    mesh: trimesh.Trimesh
    is_background: bool
    is_thin: bool
    albedo: np.ndarray
    texture: str = "none"
    texture_scale: float = 0.2
    material: Material | None = None


# ----------------------------------------------------------------------------- primitives
def _box(extents: tuple[float, float, float], centre: tuple[float, float, float]) -> trimesh.Trimesh:
    m = trimesh.creation.box(extents=extents)
    m.apply_translation(centre)
    return m


def _rod(p0: np.ndarray, p1: np.ndarray, radius: float, sections: int = 8) -> trimesh.Trimesh:
    """A cylinder of ``radius`` metres from point p0 to p1 (world)."""
    return trimesh.creation.cylinder(radius=radius, segment=np.stack([p0, p1]), sections=sections)


def _merge(parts: list[trimesh.Trimesh]) -> trimesh.Trimesh:
    return cast(trimesh.Trimesh, trimesh.util.concatenate(parts))


def _place(mesh: trimesh.Trimesh, x: float, y: float, yaw: float) -> trimesh.Trimesh:
    """Rotate ``mesh`` about the vertical axis by ``yaw`` radians, then move it to (x, y) on the floor."""
    rot = trimesh.transformations.rotation_matrix(yaw, [0, 0, 1])
    mesh = mesh.copy()
    mesh.apply_transform(rot)
    mesh.apply_translation([x, y, 0.0])
    return mesh


# ----------------------------------------------------------------------------- furniture (local frame: centred on x=y=0, floor z=0)
def make_table(rng: np.random.Generator) -> tuple[trimesh.Trimesh, bool]:
    """Table top (planar) on four thin legs. Returns (mesh, is_thin)."""
    w, d, h = rng.uniform(0.9, 1.3), rng.uniform(0.6, 0.8), rng.uniform(0.70, 0.78)
    top_t, leg_r = 0.04, rng.uniform(0.015, 0.022)
    parts = [_box((w, d, top_t), (0, 0, h - top_t / 2))]
    for sx in (-1, 1):
        for sy in (-1, 1):
            x, y = sx * (w / 2 - 0.06), sy * (d / 2 - 0.06)
            parts.append(_rod(np.array([x, y, 0.0]), np.array([x, y, h - top_t]), leg_r))
    return _merge(parts), True


def make_chair(rng: np.random.Generator) -> tuple[trimesh.Trimesh, bool]:
    """Chair: seat, backrest on two thin posts, four thin legs, a cross bar."""
    s, h = rng.uniform(0.40, 0.48), rng.uniform(0.43, 0.47)
    leg_r, seat_t = rng.uniform(0.010, 0.015), 0.03
    parts = [_box((s, s, seat_t), (0, 0, h - seat_t / 2))]
    for sx in (-1, 1):
        for sy in (-1, 1):
            x, y = sx * (s / 2 - 0.03), sy * (s / 2 - 0.03)
            parts.append(_rod(np.array([x, y, 0.0]), np.array([x, y, h - seat_t]), leg_r))
    back_h = rng.uniform(0.35, 0.45)
    for sx in (-1, 1):
        x, y = sx * (s / 2 - 0.03), -(s / 2 - 0.02)
        parts.append(_rod(np.array([x, y, h]), np.array([x, y, h + back_h]), leg_r))
    parts.append(_box((s, 0.025, back_h * 0.45), (0, -(s / 2 - 0.02), h + back_h * 0.72)))
    parts.append(_rod(np.array([-(s / 2 - 0.03), s / 2 - 0.03, 0.18]), np.array([s / 2 - 0.03, s / 2 - 0.03, 0.18]), leg_r * 0.8))
    return _merge(parts), True


def make_lamp(rng: np.random.Generator) -> tuple[trimesh.Trimesh, bool]:
    """Floor lamp: flat round base, a thin pole (~2.4 cm), a conical shade."""
    h, pole_r = rng.uniform(1.3, 1.6), rng.uniform(0.010, 0.014)
    base = trimesh.creation.cylinder(radius=0.15, height=0.03, sections=24)
    base.apply_translation([0, 0, 0.015])
    pole = _rod(np.array([0, 0, 0.03]), np.array([0, 0, h]), pole_r)
    shade = trimesh.creation.cone(radius=0.2, height=0.25, sections=24)
    shade.apply_transform(trimesh.transformations.rotation_matrix(np.pi, [1, 0, 0]))
    shade.apply_translation([0, 0, h + 0.2])
    return _merge([base, pole, shade]), True


def make_plant(rng: np.random.Generator) -> tuple[trimesh.Trimesh, bool]:
    """Potted plant: a pot and several thin tilted stems (~1.6 cm) each carrying a small leaf blob."""
    pot_h = rng.uniform(0.25, 0.35)
    pot = trimesh.creation.cylinder(radius=0.13, height=pot_h, sections=20)
    pot.apply_translation([0, 0, pot_h / 2])
    parts = [pot]
    for k in range(int(rng.integers(4, 7))):
        az = 2 * np.pi * k / 6 + rng.uniform(-0.3, 0.3)
        tilt = rng.uniform(0.15, 0.45)
        length = rng.uniform(0.45, 0.8)
        p0 = np.array([0.0, 0.0, pot_h])
        p1 = p0 + length * np.array([np.sin(tilt) * np.cos(az), np.sin(tilt) * np.sin(az), np.cos(tilt)])
        parts.append(_rod(p0, p1, rng.uniform(0.006, 0.009), sections=6))
        leaf = trimesh.creation.icosphere(subdivisions=1, radius=1.0)
        leaf.apply_scale([0.07, 0.04, 0.015])
        leaf.apply_translation(p1)
        parts.append(leaf)
    return _merge(parts), True


def make_fern(rng: np.random.Generator) -> tuple[trimesh.Trimesh, bool]:
    """Fern-like foliage (LLFF's fern / flower scenes): a pot and 7-10 arching fronds, each a thin rachis
    (~1 cm) carrying 8-12 pairs of thin leaflets (6 -> 2 cm long, 3 mm thick) that overlap each other
    from most viewpoints: thin structures with many depth layers and self-occlusion."""
    pot_h = rng.uniform(0.18, 0.25)
    pot = trimesh.creation.cylinder(radius=0.11, height=pot_h, sections=20)
    pot.apply_translation([0, 0, pot_h / 2])
    parts = [pot]
    n_fronds = int(rng.integers(7, 11))
    for k in range(n_fronds):
        az = 2 * np.pi * k / n_fronds + rng.uniform(-0.25, 0.25)
        tilt0, length = rng.uniform(0.2, 0.6), rng.uniform(0.4, 0.7)
        out = np.array([np.cos(az), np.sin(az), 0.0])
        side = np.array([-np.sin(az), np.cos(az), 0.0])
        n_seg = 6
        pts = [np.array([0.0, 0.0, pot_h])]
        for j in range(1, n_seg + 1):  # the frond arches outwards and droops towards its tip
            tilt = tilt0 + 0.9 * j / n_seg
            d = np.sin(tilt) * out + np.cos(tilt) * np.array([0.0, 0.0, 1.0])
            pts.append(pts[-1] + d * length / n_seg)
        for a, b in zip(pts[:-1], pts[1:]):
            parts.append(_rod(a, b, 0.004, sections=5))
        n_pairs = int(rng.integers(8, 13))
        for j in range(n_pairs):
            u = (j + 1) / (n_pairs + 1)
            seg = min(int(u * n_seg), n_seg - 1)
            frac = u * n_seg - seg
            at = pts[seg] + frac * (pts[seg + 1] - pts[seg])
            axis = pts[seg + 1] - pts[seg]
            axis = axis / np.linalg.norm(axis)
            leaf_len = 0.06 - 0.04 * u
            for sgn in (-1.0, 1.0):
                direction = sgn * side + 0.35 * axis
                direction = direction / np.linalg.norm(direction)
                leaf = _box((leaf_len, 0.012, 0.003), (leaf_len / 2, 0.0, 0.0))
                # local x -> direction, local y -> the frond's axis (leaflet blade in the frond's plane)
                y_ax = axis - direction * float(axis @ direction)
                y_ax = y_ax / np.linalg.norm(y_ax)
                rot = np.eye(4)
                rot[:3, 0], rot[:3, 1], rot[:3, 2] = direction, y_ax, np.cross(direction, y_ax)
                rot[:3, 3] = at
                leaf.apply_transform(rot)
                parts.append(leaf)
    return _merge(parts), True


def make_cabinet(rng: np.random.Generator) -> tuple[trimesh.Trimesh, bool]:
    """A large box: big planar faces, no thin parts."""
    w, d, h = rng.uniform(0.8, 1.4), rng.uniform(0.4, 0.6), rng.uniform(0.8, 1.8)
    return _box((w, d, h), (0, 0, h / 2)), False


def make_sofa(rng: np.random.Generator) -> tuple[trimesh.Trimesh, bool]:
    """Sofa: seat block, backrest and two arm rests (planar, no thin parts)."""
    w, d = rng.uniform(1.5, 2.0), rng.uniform(0.8, 0.95)
    parts = [
        _box((w, d, 0.42), (0, 0, 0.21)),
        _box((w, 0.2, 0.45), (0, -d / 2 + 0.1, 0.42 + 0.225)),
        _box((0.18, d, 0.22), (-w / 2 + 0.09, 0, 0.53)),
        _box((0.18, d, 0.22), (w / 2 - 0.09, 0, 0.53)),
    ]
    return _merge(parts), False


def make_shelf(rng: np.random.Generator) -> tuple[trimesh.Trimesh, bool]:
    """Open shelf: two side panels, four thin boards (2 cm), and thin back posts."""
    w, d, h = rng.uniform(0.7, 1.0), 0.35, rng.uniform(1.4, 1.9)
    parts = [_box((0.02, d, h), (-w / 2, 0, h / 2)), _box((0.02, d, h), (w / 2, 0, h / 2))]
    for z in np.linspace(0.05, h - 0.02, 4):
        parts.append(_box((w, d, 0.02), (0, 0, z)))
    return _merge(parts), True


FURNITURE = {
    "table": make_table,
    "chair": make_chair,
    "lamp": make_lamp,
    "plant": make_plant,
    "cabinet": make_cabinet,
    "sofa": make_sofa,
    "shelf": make_shelf,
    "fern": make_fern,
}

PALETTE = {
    "table": ((0.55, 0.38, 0.22), "wood"),
    "chair": ((0.35, 0.22, 0.15), "wood"),
    "lamp": ((0.85, 0.82, 0.70), "noise"),
    "plant": ((0.20, 0.50, 0.20), "noise"),
    "cabinet": ((0.75, 0.70, 0.62), "wood"),
    "sofa": ((0.30, 0.35, 0.55), "fabric"),
    "shelf": ((0.60, 0.45, 0.30), "wood"),
    "fern": ((0.25, 0.55, 0.18), "noise"),
    "mesh": ((0.70, 0.60, 0.55), "noise"),
}


def load_user_mesh(path: str | Path, size: float, where: str | Path) -> trimesh.Trimesh:
    """Load any trimesh-readable mesh, scale its largest extent to ``size`` metres and stand it on z = 0.

    Raises BenchInputError naming ``path`` if it is missing, unreadable or empty.
    """
    path = Path(path)
    if not path.exists():
        raise BenchInputError(where, f"object mesh {path} does not exist")
    try:
        mesh = trimesh.load(path, force="mesh", process=True)
    except Exception as exc:  # trimesh raises many types for bad files
        raise BenchInputError(path, f"cannot be read as a mesh ({exc})") from exc
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise BenchInputError(path, "mesh has no faces")
    if not np.all(np.isfinite(mesh.vertices)):
        raise BenchInputError(path, "mesh has NaN or inf vertices")
    extent = float(np.max(mesh.extents))
    if extent <= 0:
        raise BenchInputError(path, "mesh is degenerate (zero extent)")
    mesh = mesh.copy()
    mesh.apply_translation(-mesh.bounds.mean(axis=0))
    mesh.apply_scale(size / extent)
    mesh.apply_translation([0, 0, -mesh.bounds[0, 2]])
    return mesh


def _jitter_colour(rng: np.random.Generator, base: tuple[float, float, float], amount: float = 0.08) -> np.ndarray:
    return np.clip(np.asarray(base) + rng.uniform(-amount, amount, 3), 0.05, 0.95)


# ----------------------------------------------------------------------------- room
def build_room_shell(size: tuple[float, float, float], rng: np.random.Generator) -> list[SceneObject]:
    """Floor, ceiling and four walls of an axis-aligned room [0, sx] x [0, sy] x [0, sz] (metres).

    Walls and ceiling are textureless (the hard case for photometric reconstruction that monocular
    priors are meant to fix); the floor carries a faint tile texture.
    """
    sx, sy, sz = size
    t = 0.05
    wall_col = _jitter_colour(rng, (0.80, 0.78, 0.72), 0.05)
    shell = [
        ("floor", "floor", _box((sx, sy, t), (sx / 2, sy / 2, -t / 2)), _jitter_colour(rng, (0.55, 0.50, 0.45)), "tiles"),
        ("ceiling", "ceiling", _box((sx, sy, t), (sx / 2, sy / 2, sz + t / 2)), np.array([0.9, 0.9, 0.88]), "none"),
        ("wall_south", "wall", _box((sx, t, sz), (sx / 2, -t / 2, sz / 2)), wall_col, "none"),
        ("wall_north", "wall", _box((sx, t, sz), (sx / 2, sy + t / 2, sz / 2)), wall_col, "none"),
        ("wall_west", "wall", _box((t, sy, sz), (-t / 2, sy / 2, sz / 2)), wall_col * 0.95, "none"),
        ("wall_east", "wall", _box((t, sy, sz), (sx + t / 2, sy / 2, sz / 2)), wall_col * 0.97, "none"),
    ]
    return [
        SceneObject(name=n, category=c, mesh=m, is_background=True, is_thin=False, albedo=np.asarray(a, float), texture=tex, texture_scale=0.5)
        for n, c, m, a, tex in shell
    ]


def _footprint(mesh: trimesh.Trimesh) -> np.ndarray:
    return mesh.bounds[:, :2]  # (2, 2): min xy, max xy


def place_on_floor(
    items: list[tuple[str, str, trimesh.Trimesh, bool]],
    area_min: np.ndarray,
    area_max: np.ndarray,
    rng: np.random.Generator,
    keep_clear: list[np.ndarray] | None = None,
    margin: float = 0.1,
    tries: int = 200,
) -> list[tuple[str, str, trimesh.Trimesh, bool]]:
    """Place local-frame meshes at random non-overlapping floor positions inside [area_min, area_max] (xy).

    Footprints (axis-aligned after rotation) must not overlap each other (with ``margin`` metres)
    nor any ``keep_clear`` box ((2, 2) xy min/max). Items that cannot be placed are dropped.
    """
    placed: list[tuple[str, str, trimesh.Trimesh, bool]] = []
    boxes: list[np.ndarray] = list(keep_clear or [])
    for name, category, mesh, thin in items:
        for _ in range(tries):
            yaw = rng.choice([0.0, np.pi / 2, np.pi, 3 * np.pi / 2]) + rng.uniform(-0.3, 0.3)
            x, y = rng.uniform(area_min[0], area_max[0]), rng.uniform(area_min[1], area_max[1])
            cand = _place(mesh, x, y, yaw)
            fp = _footprint(cand)
            if np.any(fp[0] < area_min) or np.any(fp[1] > area_max):
                continue
            if any(np.all(fp[0] - margin < b[1]) and np.all(b[0] < fp[1] + margin) for b in boxes):
                continue
            boxes.append(fp)
            placed.append((name, category, cand, thin))
            break
    return placed
