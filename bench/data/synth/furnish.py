"""Furniture as rooms have it: the ``walls_and_table`` arrangement of a room.

Cabinets, shelves, the sofa (and any other piece, a user's mesh too) stand with their backs to a wall
and a small gap; lamps and plants stand in a corner or beside a piece on a wall; the first table stands
in the free floor with the chairs around it, each facing the table and pushed slightly under its top.
The table group keeps a walkway of ``2 x clearance`` metres to everything along the walls, so that a
hand-held walk can circle it (:func:`bench.data.synth.cameras.room_walk`) and see each piece from
several sides. Each wall piece goes to the wall that leaves the table group the most room.

Local frames of the furniture (bench.data.synth.geometry): centred near x = y = 0, floor at z = 0, the
back (a sofa's or a chair's backrest) towards local -y, the front towards +y. World: the room
``[0, sx] x [0, sy]``, z up, metres.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
import trimesh

from bench.data.synth.floorplan import Footprint, enclosing, rotation_2d
from bench.data.synth.geometry import _place

Item = tuple[str, str, trimesh.Trimesh, bool]  # (name, category, mesh, is_thin)

WALL_GAP = 0.02        # m between a wall and the back of a piece (assumed: pushed back to the skirting board)
PIECE_GAP = 0.05       # m between neighbouring pieces (assumed)
CHAIR_PUSH = (0.08, 0.04, 0.0)  # m a seat's front edge reaches under the table top: the first that misses the legs (assumed)
CHAIR_TURN_DEG = 5.0   # a chair faces the table within this many degrees (assumed: chairs are not set square)
TABLE_TURN_DEG = 3.0   # the table's long axis within this many degrees of the room's long axis (assumed)
WALKWAY_SPARE = 0.05   # m added to the 2 x clearance walkway so a walk fits it with room to spare
CORNER_CATEGORIES = ("lamp", "plant", "fern")


@dataclass(frozen=True)
class Wall:
    """One wall of the room seen from above.

    Attributes:
        name: ``south`` (y = 0), ``north`` (y = sy), ``west`` (x = 0) or ``east`` (x = sx).
        origin: (2,) the world point at along-coordinate 0; along: (2,) unit vector along the wall;
        inward: (2,) unit normal into the room; yaw: the yaw (radians) that turns a piece's back
        (local -y) to this wall; length: metres.
    """

    name: str
    origin: np.ndarray
    along: np.ndarray
    inward: np.ndarray
    yaw: float
    length: float

    def depth_of(self, points: np.ndarray) -> np.ndarray:
        """(N,) distance of (N, 2) points from the wall into the room, metres."""
        return (np.asarray(points) - self.origin) @ self.inward


def room_walls(size: Sequence[float]) -> list[Wall]:
    """The four walls of the room ``[0, sx] x [0, sy]``."""
    sx, sy = float(size[0]), float(size[1])
    return [
        Wall("south", np.array([0.0, 0.0]), np.array([1.0, 0.0]), np.array([0.0, 1.0]), 0.0, sx),
        Wall("north", np.array([0.0, sy]), np.array([1.0, 0.0]), np.array([0.0, -1.0]), np.pi, sx),
        Wall("west", np.array([0.0, 0.0]), np.array([0.0, 1.0]), np.array([1.0, 0.0]), -np.pi / 2, sy),
        Wall("east", np.array([sx, 0.0]), np.array([0.0, 1.0]), np.array([-1.0, 0.0]), np.pi / 2, sy),
    ]


@dataclass
class Arrangement:
    """The furniture of a room, placed.

    Attributes:
        placed: the placed pieces, world meshes, in placement order.
        footprints: the floor rectangle of each placed piece (same order).
        roles: name -> where it stands: ``wall:<wall>``, ``corner``, ``beside:<piece>``, ``table``,
            ``chair:<table>``.
        group: the rectangle of the table with its chairs (None without a table): what a walk circles.
        dropped: names of the pieces that found no place.
    """

    placed: list[Item] = field(default_factory=list)
    footprints: list[Footprint] = field(default_factory=list)
    roles: dict[str, str] = field(default_factory=dict)
    group: Footprint | None = None
    dropped: list[str] = field(default_factory=list)

    def add(self, item: Item, x: float, y: float, yaw: float, role: str) -> None:
        name, category, mesh, thin = item
        self.placed.append((name, category, _place(mesh, x, y, yaw), thin))
        self.footprints.append(Footprint.of_placed(mesh, x, y, yaw))
        self.roles[name] = role


def _origin_for(mesh: trimesh.Trimesh, centre: np.ndarray, yaw: float) -> np.ndarray:
    """The (x, y) to move ``mesh`` to (after turning it by ``yaw``) so that its footprint is centred on ``centre``."""
    lo, hi = mesh.bounds[0, :2], mesh.bounds[1, :2]
    return np.asarray(centre) - rotation_2d(yaw) @ ((lo + hi) / 2)


# ----------------------------------------------------------------------------- the table group
@dataclass
class _Group:
    """The table and its chairs in the table's frame (table at the origin, yaw 0)."""

    members: list[tuple[Item, float, float, float, str]]  # (item, x, y, yaw, role) in the table frame
    dropped: list[str]

    def footprints(self) -> list[Footprint]:
        return [Footprint.of_placed(item[2], x, y, yaw) for item, x, y, yaw, _ in self.members]


def _table_group(table: Item, chairs: list[Item], turns: np.ndarray) -> _Group:
    """Chairs around ``table``: each on the side with the fewest chairs that still has room (long sides
    first), evenly spaced along it, facing the table (``turns``: each chair's deviation, radians) and
    pushed under the top as far as :data:`CHAIR_PUSH` allows without touching a table leg."""
    tmesh = table[2]
    half = (tmesh.bounds[1, :2] - tmesh.bounds[0, :2]) / 2
    centre = (tmesh.bounds[1, :2] + tmesh.bounds[0, :2]) / 2
    height = float(tmesh.bounds[1, 2])
    legs = tmesh.vertices[tmesh.vertices[:, 2] < 0.5 * height][:, :2]
    normals = [np.array(n, float) for n in ([(0, 1), (0, -1), (1, 0), (-1, 0)] if half[0] >= half[1] else [(1, 0), (-1, 0), (0, 1), (0, -1)])]
    side_of: list[int] = []
    members: list[tuple[Item, float, float, float, str]] = [(table, 0.0, 0.0, 0.0, "table")]
    dropped = []
    widths = [float(c[2].extents[0]) for c in chairs]
    for i, chair in enumerate(chairs):
        counts = [side_of.count(s) for s in range(4)]
        for s in sorted(range(4), key=lambda s: (counts[s], s)):
            length = 2 * float(abs(np.array([-normals[s][1], normals[s][0]]) @ half))
            on_side = [widths[j] for j, sj in enumerate(side_of) if sj == s] + [widths[i]]
            if sum(on_side) + PIECE_GAP * (len(on_side) - 1) <= length:
                side_of.append(s)
                break
        else:
            side_of.append(-1)
            dropped.append(chair[0])
    for s, n in enumerate(normals):
        seats = [i for i, si in enumerate(side_of) if si == s]
        along = np.array([-n[1], n[0]])
        length = 2 * float(abs(along @ half))
        edge = float(abs(n @ half))
        for k, i in enumerate(seats):
            chair = chairs[i]
            yaw = float(np.arctan2(n[0], -n[1]) + turns[i])  # local +y (the seat's front) towards the table
            offset = (k + 0.5) / len(seats) * length - length / 2
            lo, hi = chair[2].bounds[0, :2], chair[2].bounds[1, :2]
            front_mid = np.array([(lo[0] + hi[0]) / 2, hi[1]])
            for push in CHAIR_PUSH:
                xy = centre + n * (edge - push) + along * offset - rotation_2d(yaw) @ front_mid
                fp = Footprint.of_placed(chair[2], float(xy[0]), float(xy[1]), yaw)
                if np.all(fp.distance(legs) > 0.01):
                    break
            members.append((chair, float(xy[0]), float(xy[1]), yaw, f"chair:{table[0]}"))
    kept = [members[0]]
    for m in members[1:]:  # chairs on neighbouring sides that would touch: the later one goes
        fp = Footprint.of_placed(m[0][2], m[1], m[2], m[3])
        if any(fp.overlaps(Footprint.of_placed(o[0][2], o[1], o[2], o[3]), 0.02) for o in kept[1:]):
            dropped.append(m[0][0])
        else:
            kept.append(m)
    return _Group(kept, dropped)


# ----------------------------------------------------------------------------- walls and corners
def _band_depths(footprints: Sequence[Footprint], walls: Sequence[Wall]) -> dict[str, float]:
    """How far into the room the pieces standing against each wall reach, metres."""
    depths = {}
    for w in walls:
        reach = [float(w.depth_of(f.corners()).max()) for f in footprints if w.depth_of(f.corners()).min() <= WALL_GAP + 0.01]
        depths[w.name] = max(reach, default=0.0)
    return depths


def _slack(footprints: Sequence[Footprint], size: Sequence[float], group_extent: np.ndarray, clearance: float) -> float:
    """Room left for the table group (its axis-aligned extent ``group_extent``, metres) inside the pieces
    along the walls, with walkways of ``2 x clearance`` on every side: the smaller of the x and y slack."""
    d = _band_depths(footprints, room_walls(size))
    walkways = 2 * (2 * clearance + WALKWAY_SPARE)
    free_x = size[0] - d["west"] - d["east"] - walkways - group_extent[0]
    free_y = size[1] - d["south"] - d["north"] - walkways - group_extent[1]
    return float(min(free_x, free_y))


def _spans(wall: Wall, depth: float, half_along: float, footprints: Sequence[Footprint]) -> list[tuple[float, float]]:
    """Free intervals of the along-coordinate where a piece ``depth`` metres deep and ``2 x half_along``
    wide can stand centred against ``wall`` without coming within PIECE_GAP of another piece."""
    spans = [(half_along, wall.length - half_along)]
    for f in footprints:
        c = f.corners()
        if wall.depth_of(c).min() >= WALL_GAP + depth + PIECE_GAP:
            continue
        t = (c - wall.origin) @ wall.along
        a, b = t.min() - PIECE_GAP - half_along, t.max() + PIECE_GAP + half_along
        spans = [piece for lo, hi in spans for piece in ((lo, min(hi, a)), (max(lo, b), hi)) if piece[1] > piece[0]]
    return [s for s in spans if s[1] > s[0]]


def _draw_in(spans: list[tuple[float, float]], rng: np.random.Generator) -> float:
    """A uniform draw over the union of ``spans``."""
    lengths = np.array([b - a for a, b in spans])
    u = float(rng.uniform(0.0, lengths.sum()))
    for (a, b), length in zip(spans, lengths):
        if u <= length:
            return a + u
        u -= length
    return spans[-1][1]


def _best(candidates: list[tuple[float, tuple]]) -> tuple | None:
    """The payload of the candidate with the largest score (the first of equals), or None."""
    best: tuple[float, tuple] | None = None
    for score, payload in candidates:
        if best is None or score > best[0]:
            best = (score, payload)
    return None if best is None else best[1]


def _place_against_walls(arr: Arrangement, pieces: list[Item], size: Sequence[float], group_extent: np.ndarray,
                         clearance: float, rng: np.random.Generator) -> None:
    """Each piece (widest first) against the wall that leaves the table group the most room, at a
    uniformly drawn free position along it."""
    walls = room_walls(size)
    for item in sorted(pieces, key=lambda it: -float(it[2].extents[0])):
        mesh = item[2]
        half = (mesh.bounds[1, :2] - mesh.bounds[0, :2]) / 2
        candidates = []
        for wi in rng.permutation(len(walls)):
            wall = walls[int(wi)]
            spans = _spans(wall, 2 * half[1], half[0], arr.footprints)
            if not spans:
                continue
            centre = wall.origin + wall.along * _draw_in(spans, rng) + wall.inward * (WALL_GAP + half[1])
            xy = _origin_for(mesh, centre, wall.yaw)
            fp = Footprint.of_placed(mesh, float(xy[0]), float(xy[1]), wall.yaw)
            candidates.append((_slack([*arr.footprints, fp], size, group_extent, clearance), (xy, wall)))
        choice = _best(candidates)
        if choice is None:
            arr.dropped.append(item[0])
            continue
        xy, wall = choice
        arr.add(item, float(xy[0]), float(xy[1]), wall.yaw, f"wall:{wall.name}")


def _place_in_corners(arr: Arrangement, pieces: list[Item], size: Sequence[float], group_extent: np.ndarray,
                      clearance: float, rng: np.random.Generator) -> None:
    """Each piece (largest first) in a free corner of the room or beside a piece on a wall, the spot
    that leaves the table group the most room (equals in a random order); where no such spot leaves the
    group room enough, at the best free spot along a wall."""
    sx, sy = float(size[0]), float(size[1])
    walls = room_walls(size)
    by_name = {w.name: w for w in walls}
    for piece in sorted(pieces, key=lambda it: -float(np.prod(it[2].extents[:2]))):
        # turned first, then placed by its axis-aligned box: a round piece stands flush in its corner
        mesh = _place(piece[2], 0.0, 0.0, float(rng.uniform(0.0, 2 * np.pi)))
        item, yaw = (piece[0], piece[1], mesh, piece[3]), 0.0
        ext = mesh.extents[:2]
        slots: list[tuple[np.ndarray, str]] = []
        for cx in (WALL_GAP + ext[0] / 2, sx - WALL_GAP - ext[0] / 2):
            for cy in (WALL_GAP + ext[1] / 2, sy - WALL_GAP - ext[1] / 2):
                slots.append((np.array([cx, cy]), "corner"))
        for (name, *_), placed_fp in zip(arr.placed, arr.footprints):
            role = arr.roles[name]
            if not role.startswith("wall:"):
                continue
            wall = by_name[role.split(":")[1]]
            t = (placed_fp.corners() - wall.origin) @ wall.along
            half_along, depth = float(abs(wall.along @ ext)) / 2, float(abs(wall.inward @ ext)) / 2
            for end in (t.min() - PIECE_GAP - half_along, t.max() + PIECE_GAP + half_along):
                slots.append((wall.origin + wall.along * end + wall.inward * (WALL_GAP + depth), f"beside:{name}"))
        for wall in walls:
            half_along, depth = float(abs(wall.along @ ext)) / 2, float(abs(wall.inward @ ext)) / 2
            spans = _spans(wall, 2 * depth, half_along, arr.footprints)
            if spans:
                slots.append((wall.origin + wall.along * _draw_in(spans, rng) + wall.inward * (WALL_GAP + depth), f"wall:{wall.name}"))
        preferred: list[tuple[float, tuple]] = []
        fallback: list[tuple[float, tuple]] = []
        for si in rng.permutation(len(slots)):
            centre, role = slots[int(si)]
            xy = _origin_for(mesh, centre, yaw)
            fp = Footprint.of_placed(mesh, float(xy[0]), float(xy[1]), yaw)
            lo, hi = fp.bounds()
            if np.any(lo < 0.0) or hi[0] > sx or hi[1] > sy or any(fp.overlaps(o, PIECE_GAP) for o in arr.footprints):
                continue
            slack = _slack([*arr.footprints, fp], size, group_extent, clearance)
            (preferred if slack >= 0 and not role.startswith("wall:") else fallback).append((slack, (xy, role)))
        choice = _best(preferred) or _best(fallback)
        if choice is None:
            arr.dropped.append(item[0])
            continue
        xy, role = choice
        arr.add(item, float(xy[0]), float(xy[1]), yaw, role)


# ----------------------------------------------------------------------------- the arrangement
def arrange_walls_and_table(items: list[Item], size: Sequence[float], rng: np.random.Generator, clearance: float) -> Arrangement:
    """Place ``items`` (local-frame meshes) in the room ``[0, sx] x [0, sy]`` as rooms have them.

    The first ``table`` with every ``chair`` forms the table group (chairs without a table stand against
    a wall); lamps, plants and ferns go to corners or beside wall pieces; everything else against a wall.
    The table group stands near the middle of the free floor with ``2 x clearance`` (+ WALKWAY_SPARE)
    metres of walkway to the wall pieces on every side, its long axis along the room's; chairs that do not fit are dropped first, then the table.

    Returns:
        The :class:`Arrangement` (world meshes, footprints, roles, the group's rectangle, dropped names).
    """
    arr = Arrangement()
    tables = [i for i, it in enumerate(items) if it[1] == "table"]
    t_index = tables[0] if tables else None
    chairs = [it for it in items if it[1] == "chair"] if t_index is not None else []
    corner = [it for it in items if it[1] in CORNER_CATEGORIES]
    on_walls = [it for i, it in enumerate(items) if i != t_index and it[1] not in CORNER_CATEGORIES and not (chairs and it[1] == "chair")]

    group: _Group | None = None
    group_yaw = 0.0
    extent = np.zeros(2)
    if t_index is not None:
        group_yaw = (0.0 if size[0] >= size[1] else np.pi / 2) + float(rng.uniform(-1, 1)) * np.deg2rad(TABLE_TURN_DEG)
        turns = rng.uniform(-1, 1, len(chairs)) * np.deg2rad(CHAIR_TURN_DEG)
        group = _table_group(items[t_index], chairs, turns)
        extent = _group_box(group, group_yaw)[1] * 2

    _place_against_walls(arr, on_walls, size, extent, clearance, rng)
    _place_in_corners(arr, corner, size, extent, clearance, rng)

    if group is not None:
        depth = _band_depths(arr.footprints, room_walls(size))
        lo = np.array([depth["west"], depth["south"]]) + 2 * clearance + WALKWAY_SPARE
        hi = np.array([size[0] - depth["east"], size[1] - depth["north"]]) - 2 * clearance - WALKWAY_SPARE
        while True:
            offset, half = _group_box(group, group_yaw)
            if np.all(hi - lo >= 2 * half) or len(group.members) == 1:
                break
            group.dropped.append(group.members.pop()[0][0])  # the last chair goes first
        arr.dropped.extend(group.dropped)
        if np.all(hi - lo >= 2 * half):
            # the middle half of the free floor: tables stand near the middle of the room
            box_centre = (lo + hi) / 2 + rng.uniform(-0.25, 0.25, 2) * (hi - lo - 2 * half)
            centre = box_centre - offset
            rot = rotation_2d(group_yaw)
            for item, x, y, yaw, role in group.members:
                xy = rot @ np.array([x, y]) + centre
                arr.add(item, float(xy[0]), float(xy[1]), group_yaw + yaw, role)
            local = enclosing(group.footprints(), 0.0)
            arr.group = Footprint(rot @ local.centre + centre, group_yaw, local.half)
        else:
            arr.dropped.append(group.members[0][0][0])  # the table
    return arr


def _group_box(group: _Group, yaw: float) -> tuple[np.ndarray, np.ndarray]:
    """The group's rectangle (in the table's frame) turned by ``yaw`` about the table's centre: (offset of
    its axis-aligned box's centre from the table's origin, the box's half extents), metres."""
    rot = rotation_2d(yaw)
    corners = enclosing(group.footprints(), 0.0).corners() @ rot.T
    lo, hi = corners.min(axis=0), corners.max(axis=0)
    return (lo + hi) / 2, (hi - lo) / 2
