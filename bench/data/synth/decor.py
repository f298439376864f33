"""Wall decor of a box room: doors, windows, framed pictures, a whiteboard, wall shelves with books,
light switches, sockets and skirting boards. Real geometry (thin axis-aligned boxes 1-8 cm proud of
the wall; a wall shelf 20 cm), so the GT mesh, depth and instance maps include it.

Room: the axis-aligned box [0, sx] x [0, sy] x [0, sz] (metres, world z up, floor z = 0), the inner
wall surfaces at x = 0, x = sx, y = 0, y = sy (:func:`bench.data.synth.geometry.build_room_shell`).
Each wall has a frame (:class:`Wall`): ``u`` along the wall from ``origin``, ``z`` up, ``d`` into the
room along ``normal``; an item is placed by a rectangle [u0, u1] x [z0, z1] on its wall, and no two
rectangles of a wall overlap (5 cm apart at least); items keep 12 cm from the wall's ends (a wall
shelf its depth + 5 cm), so items on two walls meeting at a corner never touch either.

Background flags (``SceneObject.is_background``), i.e. what MonoInstance's text-prompted detector is
taken to call wall: skirting boards, switches and sockets hug the wall (1-1.5 cm proud, a few pixels)
and count as wall (background: uncertainty 0, no thin-part prior errors); doors, windows, pictures,
whiteboards and wall shelves are objects of their own in ScanNet's labels (door, window, picture,
whiteboard, shelves), so they are foreground instances. Wall shelves are thin (a 2 cm board, brackets).

All sizes are assumed typical European / North American interiors (door leaf 0.8-0.9 x 2.0-2.1 m,
handle at ~1 m, switches at ~1.1 m, sockets at ~0.3 m, window sills at 0.8-1.0 m, pictures centred at
eye height ~1.5 m, whiteboard bottom edge ~0.9 m).
"""

from __future__ import annotations

import colorsys
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import trimesh

from bench.data.synth.geometry import SceneObject, _box, _merge
from bench.data.synth.materials import Artwork, Material, Parts, Textured

EDGE_MARGIN = 0.12   # m: items keep this far from the ends of their wall
GAP = 0.05           # m: between two items' rectangles on a wall
TRIES = 60           # random positions tried per item before it is dropped
AGAINST_WALL = 0.3  # m: furniture this close to a wall takes its span of the wall (nothing hangs behind it, below its top)
DOOR_CLEARANCE = 0.85  # m: the floor in front of a door (its leaf, 0.8-0.9 m, swings over it) is kept clear
PAINT_WHITE = np.array([0.90, 0.89, 0.86])
METAL = np.array([0.62, 0.62, 0.64])


@dataclass(frozen=True)
class DecorLevel:
    """How much decor a room gets: (low, high) inclusive counts drawn uniformly per room."""

    doors: tuple[int, int]
    windows: tuple[int, int]
    pictures: tuple[int, int]
    whiteboard_prob: float
    wall_shelves: tuple[int, int]
    sockets: tuple[int, int]


# Assumed: a ScanNet room (office, dorm, classroom) shows a door, a whiteboard or a picture or two,
# a switch and sockets; a Replica apartment / office room is decorated: pictures, windows, shelves.
DECOR_LEVELS = {
    "sparse": DecorLevel(doors=(1, 1), windows=(0, 0), pictures=(0, 2), whiteboard_prob=0.4, wall_shelves=(0, 0), sockets=(1, 2)),
    "rich": DecorLevel(doors=(1, 1), windows=(1, 2), pictures=(3, 5), whiteboard_prob=0.2, wall_shelves=(1, 2), sockets=(2, 3)),
}


@dataclass(frozen=True)
class Wall:
    """One wall's frame: ``origin`` (3,) on its inner surface at the floor, ``u_axis`` (3,) along it,
    ``normal`` (3,) into the room, ``length`` m."""

    name: str
    origin: np.ndarray
    u_axis: np.ndarray
    normal: np.ndarray
    length: float

    def box(self, u0: float, u1: float, z0: float, z1: float, d0: float, d1: float) -> np.ndarray:
        """(2, 3) world min / max corners of the wall-frame box [u0, u1] x [z0, z1] x [d0, d1]."""
        corners = [self.origin + u * self.u_axis + d * self.normal + np.array([0.0, 0.0, z]) for u in (u0, u1) for z in (z0, z1) for d in (d0, d1)]
        return np.stack([np.min(corners, axis=0), np.max(corners, axis=0)])

    def point(self, u: float, z: float) -> np.ndarray:
        """(3,) the wall-surface point at (u, z)."""
        return self.origin + u * self.u_axis + np.array([0.0, 0.0, z])


def room_walls(size: tuple[float, float, float]) -> list[Wall]:
    """The four walls (south y = 0, north y = sy, west x = 0, east x = sx); u x normal = +z."""
    sx, sy, _ = size
    e = np.eye(3)
    return [
        Wall("south", np.array([0.0, 0.0, 0.0]), e[0], e[1], sx),
        Wall("north", np.array([sx, sy, 0.0]), -e[0], -e[1], sx),
        Wall("west", np.array([0.0, sy, 0.0]), -e[1], e[0], sy),
        Wall("east", np.array([sx, 0.0, 0.0]), e[1], -e[0], sy),
    ]


@dataclass(frozen=True)
class Pane:
    """A window pane: its front ``centre`` (3,), ``normal`` (3,) into the room, ``u_axis`` (3,) along
    the wall, ``half_extents`` (along u, along z) m. A window light is placed on it."""

    centre: np.ndarray
    normal: np.ndarray
    u_axis: np.ndarray
    half_extents: tuple[float, float]


@dataclass
class Decor:
    """The decor of a room.

    Attributes:
        objects: the decor items (walls' order, then kind).
        keep_clear: (2, 2) xy min / max floor boxes nothing may stand on (in front of doors, under
            wall shelves).
        panes: window panes (for window lights).
        info: counts placed and dropped per kind.
    """

    objects: list[SceneObject] = field(default_factory=list)
    keep_clear: list[np.ndarray] = field(default_factory=list)
    panes: list[Pane] = field(default_factory=list)
    info: dict[str, Any] = field(default_factory=dict)


ART = "art"  # a box painted with the item's artwork


@dataclass
class _Item:
    """A decor item in its wall's frame, centred at u = 0: boxes (u0, u1, z0, z1, d0, d1) with their
    material (None = the item's default, ``ART`` = its artwork), its rectangle on the wall and what the
    room needs of it. ``art``: the :class:`Artwork` fields other than its frame (u relative to the
    item's centre, v = z in metres), drawn when the item is made."""

    kind: str
    boxes: list[tuple[tuple[float, ...], Material | str | None]]
    default: Material
    rect: tuple[float, float, float, float]  # u0, u1, z0, z1 (relative u)
    is_background: bool
    is_thin: bool = False
    clear_depth: float = 0.0                # m of floor in front kept clear (0 = none)
    pane: tuple[float, float, float, float] | None = None  # u0, u1, z0, z1 of a window pane
    art: dict[str, Any] | None = None


def _colour(rng: np.random.Generator, sat: tuple[float, float], val: tuple[float, float]) -> np.ndarray:
    """A random colour of any hue with saturation and value drawn in the given ranges (HSV)."""
    return np.array(colorsys.hsv_to_rgb(rng.uniform(), rng.uniform(*sat), rng.uniform(*val)))


def _wood_colour(rng: np.random.Generator) -> np.ndarray:
    """A wood tone: orange-brown hues, light oak to dark walnut."""
    return np.array(colorsys.hsv_to_rgb(rng.uniform(0.05, 0.11), rng.uniform(0.4, 0.7), rng.uniform(0.3, 0.7)))


def _frame_boxes(u0: float, u1: float, z0: float, z1: float, width: float, d1: float) -> list[tuple[float, ...]]:
    """Four boxes framing the rectangle [u0, u1] x [z0, z1] from outside, ``width`` m wide, [0, d1] deep."""
    return [(u0 - width, u0, z0 - width, z1 + width, 0.0, d1), (u1, u1 + width, z0 - width, z1 + width, 0.0, d1),
            (u0, u1, z0 - width, z0, 0.0, d1), (u0, u1, z1, z1 + width, 0.0, d1)]


# ----------------------------------------------------------------------------- items (local u centred on 0)
def _door(rng: np.random.Generator, sz: float) -> _Item:
    """A door leaf 2 cm proud, a 7 cm casing 3 cm proud on three sides, a lever handle at ~1 m."""
    w, h, c = rng.uniform(0.8, 0.9), min(rng.uniform(2.0, 2.1), sz - 0.2), 0.07
    side = rng.choice([-1.0, 1.0])
    hu = side * (w / 2 - 0.08)
    lever = (hu - 0.12, hu) if side > 0 else (hu, hu + 0.12)
    handle = [(hu - 0.025, hu + 0.025, 0.96, 1.03, 0.02, 0.03), (hu - 0.008, hu + 0.008, 0.99, 1.006, 0.03, 0.07),
              (lever[0], lever[1], 0.988, 1.008, 0.06, 0.08)]
    wood = rng.random() < 0.5
    leaf: Material = Textured(_wood_colour(rng), "wood", 0.3, rng.uniform(0, 2 * np.pi)) if wood \
        else Textured(np.clip(PAINT_WHITE + rng.uniform(-0.05, 0.02, 3), 0, 1))
    casing = Textured(PAINT_WHITE)
    boxes: list[tuple[tuple[float, ...], Material | str | None]] = [(b, Textured(METAL)) for b in handle]
    boxes += [((-w / 2 - c, -w / 2, 0.0, h + c, 0.0, 0.03), casing), ((w / 2, w / 2 + c, 0.0, h + c, 0.0, 0.03), casing),
              ((-w / 2, w / 2, h, h + c, 0.0, 0.03), casing), ((-w / 2, w / 2, 0.0, h, 0.0, 0.02), None)]
    return _Item("door", boxes, leaf, (-w / 2 - c, w / 2 + c, 0.0, h + c), is_background=False, clear_depth=DOOR_CLEARANCE)


def _window(rng: np.random.Generator, sz: float) -> _Item:
    """A pane 1 cm proud in a 5 cm frame (4 cm proud) with a mullion and a transom, and a sill."""
    w, z0, f = rng.uniform(0.9, 1.5), rng.uniform(0.8, 1.0), 0.05
    h = min(rng.uniform(1.0, 1.4), sz - 0.2 - f - z0)
    boxes: list[tuple[tuple[float, ...], Material | str | None]] = [((-w / 2, w / 2, z0, z0 + h, 0.0, 0.01), ART)]
    boxes += [(b, None) for b in _frame_boxes(-w / 2, w / 2, z0, z0 + h, f, 0.04)]
    if w > 1.0:
        boxes.append(((-0.02, 0.02, z0, z0 + h, 0.0, 0.035), None))
    boxes.append(((-w / 2, w / 2, z0 + 0.65 * h - 0.02, z0 + 0.65 * h + 0.02, 0.0, 0.035), None))
    boxes.append(((-w / 2 - f - 0.04, w / 2 + f + 0.04, z0 - f - 0.03, z0 - f, 0.0, 0.06), None))  # sill
    ground, sky = _colour(rng, (0.2, 0.5), (0.35, 0.6)), np.array([0.80, 0.88, 0.97])
    horizon = z0 + rng.uniform(0.2, 0.45) * h
    trees = rng.uniform([-w / 2, z0], [w / 2, horizon], (int(rng.integers(1, 4)), 2))
    art = dict(background=ground, bands=np.array([horizon]), band_colours=sky[None], band_softness=0.08, blobs=trees,
               blob_radii=rng.uniform(0.08, 0.2, len(trees)), blob_colours=np.array([_colour(rng, (0.3, 0.6), (0.25, 0.5)) for _ in trees]))
    return _Item("window", boxes, Textured(PAINT_WHITE), (-w / 2 - f - 0.04, w / 2 + f + 0.04, z0 - f - 0.03, z0 + h + f),
                 is_background=False, pane=(-w / 2, w / 2, z0, z0 + h), art=art)


def _picture(rng: np.random.Generator, sz: float) -> _Item:
    """A framed picture: canvas 1.5 cm proud inside a 2-5 cm frame 3 cm proud, centred at eye height;
    the canvas shows soft colour blobs, a landscape's bands or a poster's bold strokes."""
    w, h, f = rng.uniform(0.3, 0.9), rng.uniform(0.25, 0.7), rng.uniform(0.02, 0.05)
    zc = float(np.clip(rng.uniform(1.35, 1.65), 0.9 + h / 2 + f, sz - 0.2 - h / 2 - f))
    z0 = zc - h / 2
    kind = rng.choice(["blobs", "landscape", "poster"])
    frame = Textured(_wood_colour(rng), "wood", 0.1, rng.uniform(0, 2 * np.pi)) if rng.random() < 0.5 else Textured(_colour(rng, (0.0, 0.3), (0.05, 0.9)))

    n_blobs = int(rng.integers(3, 7)) if kind == "blobs" else int(rng.integers(0, 3))
    blobs = rng.uniform([-w / 2, z0], [w / 2, z0 + h], (n_blobs, 2))
    art: dict[str, Any] = dict(background=_colour(rng, (0.1, 0.8), (0.15, 0.95)), blobs=blobs,
                               blob_radii=rng.uniform(0.1, 0.35, n_blobs) * min(w, h),
                               blob_colours=np.array([_colour(rng, (0.4, 0.95), (0.1, 1.0)) for _ in range(n_blobs)]).reshape(-1, 3))
    if kind == "landscape":
        art.update(bands=np.sort(z0 + rng.uniform(0.2, 0.8, 2) * h), band_colours=np.array([_colour(rng, (0.3, 0.8), (0.3, 0.9)) for _ in range(2)]))
    elif kind == "poster":
        n = int(rng.integers(2, 5))
        art.update(strokes=rng.uniform([-w / 2, z0], [w / 2, z0 + h], (n, 2, 2)), stroke_widths=rng.uniform(0.03, 0.08, n),
                   stroke_colours=np.array([_colour(rng, (0.5, 1.0), (0.05, 1.0)) for _ in range(n)]))
    boxes: list[tuple[tuple[float, ...], Material | str | None]] = [((-w / 2, w / 2, z0, z0 + h, 0.0, 0.015), ART)]
    boxes += [(b, None) for b in _frame_boxes(-w / 2, w / 2, z0, z0 + h, f, 0.03)]
    return _Item("picture", boxes, frame, (-w / 2 - f, w / 2 + f, z0 - f, z0 + h + f), is_background=False, art=art)


def _whiteboard(rng: np.random.Generator, sz: float) -> _Item:
    """A whiteboard 1.5 cm proud in a 2 cm aluminium frame, a pen tray, and a few lines of writing and a
    diagram (marker strokes 1.5-3 cm wide: wide enough not to alias at the benchmark's resolutions)."""
    w, h = rng.uniform(1.2, 2.0), rng.uniform(0.9, 1.2)
    z0 = rng.uniform(0.85, 1.0)
    h = min(h, sz - 0.2 - z0)
    ink = np.array([[0.10, 0.15, 0.50], [0.08, 0.08, 0.10], [0.60, 0.10, 0.10], [0.10, 0.45, 0.20]])

    strokes, colours = [], []
    for line in range(int(rng.integers(2, 5))):  # lines of "handwriting": zigzags
        v = z0 + h * (0.85 - 0.15 * line) + rng.uniform(-0.02, 0.02)
        u = -w / 2 + rng.uniform(0.08, 0.3)
        c = ink[rng.integers(len(ink))]
        for _ in range(int(rng.integers(4, 9))):
            du = rng.uniform(0.04, 0.1)
            strokes.append([[u, v + rng.uniform(-0.03, 0.03)], [u + du, v + rng.uniform(-0.03, 0.03)]])
            colours.append(c)
            u += du + rng.uniform(0.0, 0.05)
    bx, by = rng.uniform([0.0, z0 + 0.1], [w / 2 - 0.4, z0 + 0.3])  # a box diagram on the right half
    bw, bh = rng.uniform(0.2, 0.35), rng.uniform(0.12, 0.25)
    corners = [[bx, by], [bx + bw, by], [bx + bw, by + bh], [bx, by + bh]]
    c = ink[rng.integers(len(ink))]
    for i in range(4):
        strokes.append([corners[i], corners[(i + 1) % 4]])
        colours.append(c)
    art = dict(background=np.array([0.93, 0.94, 0.94]), strokes=np.array(strokes), stroke_widths=rng.uniform(0.015, 0.03, len(strokes)),
               stroke_colours=np.array(colours))
    boxes: list[tuple[tuple[float, ...], Material | str | None]] = [((-w / 2, w / 2, z0, z0 + h, 0.0, 0.015), ART)]
    boxes += [(b, None) for b in _frame_boxes(-w / 2, w / 2, z0, z0 + h, 0.02, 0.025)]
    boxes.append(((-w / 2 + 0.1, w / 2 - 0.1, z0 - 0.05, z0 - 0.02, 0.0, 0.06), None))  # pen tray
    return _Item("whiteboard", boxes, Textured(np.array([0.72, 0.73, 0.75])), (-w / 2 - 0.02, w / 2 + 0.02, z0 - 0.05, z0 + h + 0.02),
                 is_background=False, art=art)


def _wall_shelf(rng: np.random.Generator, sz: float) -> _Item:
    """A 2 cm wooden board 20 cm deep on two brackets, 1.6-1.8 m up, with a row of books (2-5 cm thick,
    14-24 cm tall, gaps now and then)."""
    w = rng.uniform(0.6, 1.0)
    zb = min(rng.uniform(1.6, 1.8), sz - 0.4)
    boxes: list[tuple[tuple[float, ...], Material | str | None]] = []
    u = -w / 2 + 0.03
    while True:
        t, bh, bd = rng.uniform(0.02, 0.05), rng.uniform(0.14, 0.24), rng.uniform(0.12, 0.18)
        if u + t > w / 2 - 0.03:
            break
        boxes.append(((u, u + t, zb + 0.02, zb + 0.02 + bh, 0.01, 0.01 + bd), Textured(_colour(rng, (0.3, 0.8), (0.2, 0.8)))))
        u += t + (rng.uniform(0.05, 0.15) if rng.random() < 0.15 else 0.002)
    boxes.append(((-w / 2, w / 2, zb, zb + 0.02, 0.0, 0.2), None))
    for bu in (-w / 2 + 0.1, w / 2 - 0.12):
        boxes.append(((bu, bu + 0.02, zb - 0.15, zb, 0.0, 0.15), None))
    wood = Textured(_wood_colour(rng), "wood", 0.15, rng.uniform(0, 2 * np.pi))
    return _Item("wall_shelf", boxes, wood, (-w / 2, w / 2, zb - 0.15, zb + 0.27), is_background=False, is_thin=True, clear_depth=0.2)


def _plate(kind: str, zc: float) -> _Item:
    """A switch (a rocker) or a socket (a recessed face) on an 8 x 8 cm plate 1 cm proud centred at zc."""
    inner = (-0.015, 0.015, zc - 0.025, zc + 0.025, 0.01, 0.016) if kind == "switch" else (-0.024, 0.024, zc - 0.024, zc + 0.024, 0.01, 0.013)
    return _Item(kind, [(inner, Textured(PAINT_WHITE * 0.9)), ((-0.04, 0.04, zc - 0.04, zc + 0.04, 0.0, 0.01), None)],
                 Textured(PAINT_WHITE), (-0.04, 0.04, zc - 0.04, zc + 0.04), is_background=True)


# ----------------------------------------------------------------------------- placement
def _free(rects: list[tuple[float, ...]], r: tuple[float, ...]) -> bool:
    return all(not (r[0] - GAP < o[1] and o[0] < r[1] + GAP and r[2] - GAP < o[3] and o[2] < r[3] + GAP) for o in rects)


def _materialise(item: _Item, wall: Wall, uc: float, name: str) -> SceneObject:
    """The item at wall position ``uc`` as a SceneObject (its boxes merged; materials by :class:`Parts`)."""
    meshes, boxes, materials = [], [], []
    for (u0, u1, z0, z1, d0, d1), mat in item.boxes:
        b = wall.box(uc + u0, uc + u1, z0, z1, d0, d1)
        meshes.append(_box(tuple(b[1] - b[0]), tuple(b.mean(axis=0))))
        if mat is not None:
            boxes.append(b)
            materials.append(Artwork(wall.point(uc, 0.0), wall.u_axis, np.array([0.0, 0.0, 1.0]), **(item.art or {})) if isinstance(mat, str) else mat)
    mesh: trimesh.Trimesh = _merge(meshes)
    material = Parts(item.default, np.array(boxes).reshape(-1, 2, 3), tuple(materials))
    colour = np.asarray(item.default.albedo(mesh.vertices[:1])[0]) if len(mesh.vertices) else np.zeros(3)
    return SceneObject(name, item.kind, mesh, is_background=item.is_background, is_thin=item.is_thin, albedo=colour, material=material)


def _skirting(wall: Wall, index: int, height: float, cuts: list[tuple[float, float]], colour: Material) -> SceneObject | None:
    """The skirting board of one wall (``height`` m, 1.5 cm proud), interrupted by doors (``cuts``:
    u intervals); walls 2 and 3 stop 1.5 cm short of the corners (no overlap with walls 0 and 1's)."""
    end = 0.015 if index >= 2 else 0.0
    spans, start = [], end
    for a, b in sorted(cuts):
        if a > start:
            spans.append((start, a))
        start = max(start, b)
    if wall.length - end > start:
        spans.append((start, wall.length - end))
    meshes = []
    for a, b in spans:
        box = wall.box(a, b, 0.0, height, 0.0, 0.015)
        meshes.append(_box(tuple(box[1] - box[0]), tuple(box.mean(axis=0))))
    if not meshes:
        return None
    mesh = _merge(meshes)
    return SceneObject(f"skirting_{wall.name}", "skirting", mesh, is_background=True, is_thin=False,
                       albedo=np.asarray(colour.albedo(mesh.vertices[:1])[0]), material=colour)


def _place(item: _Item, walls: list[Wall], rects: list[list[tuple[float, ...]]], rng: np.random.Generator,
           door_taken: list[list[tuple[float, ...]]] | None = None) -> tuple[int, float] | None:
    """A free (wall index, u centre) for ``item`` (recorded in ``rects``), or None after ``TRIES``
    tries. Doors sit near a corner (their casing 12-40 cm from the wall's end) or, in a third of the
    tries, anywhere along the wall; they cut the skirting and also avoid ``door_taken`` (per wall, the
    spans of furniture standing on the floor in front of them)."""
    rel = item.rect
    margin = EDGE_MARGIN + (item.clear_depth if item.kind == "wall_shelf" else 0.0)
    for _ in range(TRIES):
        wi = int(rng.integers(len(walls)))
        lo, hi = margin - rel[0], walls[wi].length - margin - rel[1]
        if hi < lo:
            continue
        uc = float(rng.uniform(lo, hi))
        if item.kind == "door":
            where = rng.random()
            if where < 2 / 3:
                uc = float(lo + rng.uniform(0.0, 0.28)) if where < 1 / 3 else float(hi - rng.uniform(0.0, 0.28))
        r = (uc + rel[0], uc + rel[1], rel[2], rel[3])
        if _free(rects[wi][1:] + (door_taken[wi] if door_taken else []) if item.kind == "door" else rects[wi], r):
            rects[wi].append(r)
            return wi, uc
    return None


def _switch_beside(door: _Item, wi: int, uc: float, walls: list[Wall], rects: list[list[tuple[float, ...]]],
                   rng: np.random.Generator) -> tuple[_Item, int, float] | None:
    """A light switch at 1.1 m, 15 cm beside the door's casing (a random side first), or None."""
    switch = _plate("switch", 1.1)
    for side in rng.permutation([-1.0, 1.0]):
        su = uc + side * ((door.rect[1] - door.rect[0]) / 2 + 0.15)
        r = (su - 0.04, su + 0.04, 1.06, 1.14)
        if EDGE_MARGIN <= r[0] and r[1] <= walls[wi].length - EDGE_MARGIN and _free(rects[wi], r):
            rects[wi].append(r)
            return switch, wi, su
    return None


def furniture_rects(walls: list[Wall], obstacles: Sequence[np.ndarray], reach: float) -> list[list[tuple[float, ...]]]:
    """Per wall, the (u0, u1, z0, z1) rectangles taken by furniture: each obstacle box ((2, 3) world
    min / max) that comes within ``reach`` metres of the wall covers its extent along the wall, from the
    floor to its top (a picture may hang above a sofa; a door may not open onto a table)."""
    rects: list[list[tuple[float, ...]]] = [[] for _ in walls]
    for box in obstacles:
        corners = np.array([[x, y] for x in box[:, 0] for y in box[:, 1]])
        for wi, wall in enumerate(walls):
            rel = corners - wall.origin[:2]
            depth = rel @ wall.normal[:2]
            if float(depth.min()) < reach:
                u = rel @ wall.u_axis[:2]
                rects[wi].append((float(u.min()), float(u.max()), 0.0, float(box[1, 2])))
    return rects


def build_decor(size: tuple[float, float, float], level: str, rng: np.random.Generator, obstacles: Sequence[np.ndarray] = ()) -> Decor:
    """The decor of the box room of ``size`` (sx, sy, sz) m at ``level`` (``"none"`` or a key of
    ``DECOR_LEVELS``), drawn from ``rng`` (nothing is drawn for ``"none"``). ``obstacles``: (2, 3) world
    boxes of the furniture standing in the room (:func:`furniture_rects`): decor avoids the wall spans
    taken by furniture against the wall (within ``AGAINST_WALL``), doors also those of furniture on the
    floor in front of them (within ``DOOR_CLEARANCE``).

    Items are placed in the order door (with its light switch beside it), windows, whiteboard, wall
    shelves, pictures, sockets (larger first), each at a random wall and position that is free
    (:data:`TRIES` tries, else dropped); then the skirting boards (cut at doors)."""
    if level == "none":
        return Decor()
    spec = DECOR_LEVELS[level]
    sz = size[2]
    walls = room_walls(size)
    counts = {"door": int(rng.integers(spec.doors[0], spec.doors[1] + 1)), "window": int(rng.integers(spec.windows[0], spec.windows[1] + 1)),
              "whiteboard": int(rng.random() < spec.whiteboard_prob),
              "wall_shelf": int(rng.integers(spec.wall_shelves[0], spec.wall_shelves[1] + 1)),
              "picture": int(rng.integers(spec.pictures[0], spec.pictures[1] + 1)), "socket": int(rng.integers(spec.sockets[0], spec.sockets[1] + 1))}
    makers = {"door": _door, "window": _window, "whiteboard": _whiteboard, "wall_shelf": _wall_shelf, "picture": _picture,
              "socket": lambda r, z: _plate("socket", 0.3)}
    skirting_h = float(rng.uniform(0.07, 0.12))
    taken = furniture_rects(walls, obstacles, AGAINST_WALL)
    door_taken = furniture_rects(walls, obstacles, DOOR_CLEARANCE)
    # the skirting band first (a door ignores it: rects[wi][1:]), then the furniture's spans
    rects: list[list[tuple[float, ...]]] = [[(0.0, w.length, 0.0, skirting_h), *taken[wi]] for wi, w in enumerate(walls)]
    placed: list[tuple[_Item, int, float]] = []
    dropped: dict[str, int] = {}
    for kind, n in counts.items():
        for _ in range(n):
            item = makers[kind](rng, sz)
            at = _place(item, walls, rects, rng, door_taken)
            if at is None:
                dropped[kind] = dropped.get(kind, 0) + 1
                continue
            placed.append((item, *at))
            if kind == "door":  # its light switch, before anything else takes the spot
                switch = _switch_beside(item, *at, walls, rects, rng)
                if switch is None:
                    dropped["switch"] = dropped.get("switch", 0) + 1
                else:
                    placed.append(switch)

    decor = Decor(info={"placed": {}, "dropped": dropped, "skirting_height_m": skirting_h})
    names: dict[str, int] = {}
    for item, wi, uc in sorted(placed, key=lambda p: (p[1], p[2])):
        k = names.get(item.kind, 0)
        names[item.kind] = k + 1
        decor.objects.append(_materialise(item, walls[wi], uc, f"{item.kind}_{k}"))
        wall = walls[wi]
        if item.clear_depth > 0:
            b = wall.box(uc + item.rect[0], uc + item.rect[1], 0.0, 0.0, 0.0, item.clear_depth)
            decor.keep_clear.append(b[:, :2])
        if item.pane is not None:
            u0, u1, z0, z1 = item.pane
            centre = wall.point(uc + (u0 + u1) / 2, (z0 + z1) / 2) + 0.011 * wall.normal
            decor.panes.append(Pane(centre, wall.normal.copy(), wall.u_axis.copy(), ((u1 - u0) / 2, (z1 - z0) / 2)))
    decor.info["placed"] = dict(sorted(names.items()))
    finish = Textured(PAINT_WHITE) if rng.random() < 0.7 else Textured(_wood_colour(rng), "wood", 0.2)
    for wi, wall in enumerate(walls):
        cuts = [(uc + it.rect[0], uc + it.rect[1]) for it, w, uc in placed if w == wi and it.kind == "door"]
        skirting = _skirting(wall, wi, skirting_h, cuts, finish)
        if skirting is not None:
            decor.objects.append(skirting)
    return decor
