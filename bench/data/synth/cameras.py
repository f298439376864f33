"""Camera placement: look-at poses (OpenCV axes) and the paths of the three scene kinds (a room has two:
the hand-held walk around the room, :func:`room_walk`, and the loop in its middle, :func:`room_path`).

All poses are (4, 4) float64 camera-to-world matrices, OpenCV axes (x right, y down, z forward),
world z up, metres.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
from scipy.ndimage import gaussian_filter1d

from bench.data.synth.floorplan import Footprint, clearance
from metrics.camera import look_at


def intrinsics(width: int, height: int, hfov_deg: float) -> np.ndarray:
    """(3, 3) pinhole K for a horizontal field of view in degrees; principal point at the image centre."""
    fx = 0.5 * width / np.tan(np.deg2rad(hfov_deg) / 2)
    return np.array([[fx, 0.0, (width - 1) / 2], [0.0, fx, (height - 1) / 2], [0.0, 0.0, 1.0]])


def room_path(
    size: tuple[float, float, float],
    n_views: int,
    rng: np.random.Generator,
    height_range: tuple[float, float] = (1.2, 1.6),
    jitter: float = 0.15,
    radius_frac: float = 0.12,
) -> np.ndarray:
    """A hand-held-like loop inside an axis-aligned room [0, sx] x [0, sy] x [0, sz].

    Cameras walk an ellipse around the room centre (radii ``radius_frac`` * room size) and look across the room
    at points 0.5-1.0 m high on the far side, so every view sees furniture, floor and walls.
    ``jitter`` (metres) perturbs positions and targets (larger = shakier, ScanNet-like).

    Returns:
        (n_views, 4, 4) camera-to-world poses.
    """
    sx, sy, _ = size
    centre = np.array([sx / 2, sy / 2])
    phase0 = rng.uniform(0, 2 * np.pi)
    poses = []
    for i in range(n_views):
        a = phase0 + 2 * np.pi * i / n_views
        eye_xy = centre + np.array([radius_frac * sx * np.cos(a), radius_frac * sy * np.sin(a)]) + rng.normal(0, jitter * 0.5, 2)
        eye = np.array([*eye_xy, rng.uniform(*height_range)])
        look_a = a + np.pi + rng.uniform(-0.5, 0.5)
        tgt_xy = centre + np.array([0.35 * sx * np.cos(look_a), 0.35 * sy * np.sin(look_a)]) + rng.normal(0, jitter, 2)
        target = np.array([*tgt_xy, rng.uniform(0.5, 1.0)])
        poses.append(look_at(eye, target))
    return np.stack(poses)


# Aim points of a room walk (assumed: a person scanning a room aims at the furniture in the middle,
# the table top and the seats, and at the walls a little below eye height, a few metres away).
WALK_FOCUS_HEIGHT = 0.6    # m: the table group is looked at around this height
WALK_WALL_HEIGHT = 1.0     # m: the walls and the pieces along them around this height ...
WALK_WALL_DISTANCE = 2.5   # m: ... this far away (sets the slight downward pitch of those views)
# At least this many frames per turn from the group to the walls and back: fewer frames alias the turning
# into jumps of 60+ deg between consecutive frames that share little (measured on scannet_like_tiny:
# 16 frames, 3 turns: consecutive frames share ~0 %, the instance association's ARI drops 0.99 -> 0.84).
WALK_FRAMES_PER_SWEEP = 12


def walk_sweeps(sweeps: int, n_views: int) -> int:
    """The turns a walk of ``n_views`` frames makes: ``sweeps``, but at most one per
    :data:`WALK_FRAMES_PER_SWEEP` frames (and at least one when ``sweeps`` > 0)."""
    return 0 if sweeps <= 0 else max(1, min(sweeps, n_views // WALK_FRAMES_PER_SWEEP))


def walk_loop(
    size: Sequence[float],
    obstacles: Sequence[Footprint] = (),
    around: Footprint | None = None,
    min_clearance: float = 0.3,
    n_rays: int = 360,
    step: float = 0.01,
    wall_distance: float | None = None,
) -> np.ndarray:
    """The closed floor path of a walk through the room ``[0, sx] x [0, sy]``: around the rectangle
    ``around`` (the table group; None = the middle of the room), midway between it and what stands along
    the walls (``wall_distance`` None) or ``wall_distance`` metres from the walls, smoothed, never closer
    than ``min_clearance`` metres to an obstacle or a wall.

    On each of ``n_rays`` rays from the centre of ``around`` the walkable stretch beyond it is found
    (``step`` metres resolution); the path runs through the middle of those stretches, or where the ray
    meets the room's outline inset by ``wall_distance``, smoothed over about 10 degrees and kept inside
    the stretches (so where the group leaves less room, the path runs nearer the walls).

    Returns:
        (n_rays, 2) world x, y of the closed path, counter-clockwise.

    Raises:
        ValueError: some ray finds no walkable stretch (the room is too full for a walk around it).
    """
    sx, sy = float(size[0]), float(size[1])
    focus = around.centre if around is not None else np.array([sx / 2, sy / 2])
    theta = np.linspace(0.0, 2 * np.pi, n_rays, endpoint=False)
    dirs = np.stack([np.cos(theta), np.sin(theta)], axis=1)
    r = np.arange(0.0, float(np.hypot(sx, sy)), step)
    pts = (focus[None, None, :] + r[None, :, None] * dirs[:, None, :]).reshape(-1, 2)
    free = (clearance(pts, size, obstacles) >= min_clearance).reshape(n_rays, len(r))
    if around is not None:
        start = np.argmax((around.distance(pts) >= min_clearance).reshape(n_rays, len(r)), axis=1)
    else:  # no group in the middle: walk no nearer to the centre than 40 % of the way to the walls
        start = np.searchsorted(r, 0.4 * _ray_exit(focus, dirs, 0.0, sx, 0.0, sy))
    inner, outer = np.zeros(n_rays), np.zeros(n_rays)
    for k in range(n_rays):
        walkable = np.flatnonzero(free[k, start[k]:])
        if walkable.size == 0 and around is None:  # a cramped room: the first walkable floor out from the centre
            start[k] = 0
            walkable = np.flatnonzero(free[k])
        if walkable.size == 0:
            raise ValueError(f"no walkable floor at {np.degrees(theta[k]):.0f} deg from the walk's centre with {min_clearance:g} m clearance")
        a = start[k] + walkable[0]
        blocked = np.flatnonzero(~free[k, a:])
        b = a + (blocked[0] if blocked.size else len(r) - a)
        inner[k], outer[k] = r[a], r[b - 1]
    radius = (inner + outer) / 2 if wall_distance is None else _ray_exit(focus, dirs, wall_distance, sx - wall_distance, wall_distance, sy - wall_distance)
    for _ in range(3):
        radius = np.clip(gaussian_filter1d(radius, sigma=n_rays / 36, mode="wrap"), inner, outer)
    return focus + radius[:, None] * dirs


def _ray_exit(origin: np.ndarray, dirs: np.ndarray, x0: float, x1: float, y0: float, y1: float) -> np.ndarray:
    """(R,) distance along each unit direction ``dirs`` (R, 2) from ``origin`` (2,) to where it leaves the
    rectangle ``[x0, x1] x [y0, y1]`` (0 where ``origin`` lies outside it in that direction)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        tx = np.where(dirs[:, 0] > 0, (x1 - origin[0]) / dirs[:, 0], np.where(dirs[:, 0] < 0, (x0 - origin[0]) / dirs[:, 0], np.inf))
        ty = np.where(dirs[:, 1] > 0, (y1 - origin[1]) / dirs[:, 1], np.where(dirs[:, 1] < 0, (y0 - origin[1]) / dirs[:, 1], np.inf))
    return np.maximum(np.minimum(tx, ty), 0.0)


def room_walk(
    size: Sequence[float],
    n_views: int,
    rng: np.random.Generator,
    obstacles: Sequence[Footprint] = (),
    around: Footprint | None = None,
    min_clearance: float = 0.3,
    height_range: tuple[float, float] = (1.2, 1.7),
    jitter: float = 0.05,
    shake_deg: float = 2.0,
    sweeps: int = 3,
    sweep_deg: float = 100.0,
    wall_distance: float | None = None,
) -> np.ndarray:
    """A hand-held scan of a room: one walk around :func:`walk_loop`'s path (``wall_distance``: see there),
    frames in capture order.

    The operator walks the loop at a steady pace (``n_views`` frames equally spaced along it, a random
    start and direction) and turns the camera back and forth between the table group in the middle
    (heading towards ``around``'s centre) and the walls, corners and the pieces along them: the heading is
    the direction to the centre plus ``sweep_deg * sin(2 pi k t + phase)`` (t the fraction of the loop
    walked), so it turns smoothly, k = :func:`walk_sweeps` (``sweeps``, fewer for few frames) times per
    loop. Pitch looks down at the group (:data:`WALK_FOCUS_HEIGHT`) when facing it and slightly down at
    the walls otherwise; the height wanders smoothly within ``height_range`` (m). A shaky hand adds Gaussian position noise of std
    ``jitter`` metres (horizontal; half of it vertical; dropped where it would break ``min_clearance``)
    and roll / pitch / heading noise of std ``shake_deg`` degrees (0 and 0: a smooth synthetic walk).

    Returns:
        (n_views, 4, 4) camera-to-world poses (OpenCV axes, world z up, metres).

    Raises:
        ValueError: no walkable loop (see :func:`walk_loop`).
    """
    loop = walk_loop(size, obstacles, around, min_clearance, wall_distance=wall_distance)
    focus = around.centre if around is not None else np.array([size[0] / 2, size[1] / 2])
    closed = np.concatenate([loop, loop[:1]])
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(closed, axis=0), axis=1))])
    start, direction = rng.uniform(0.0, 1.0), rng.choice([-1.0, 1.0])
    sweep_phase, height_phase, height_cycles = rng.uniform(0, 2 * np.pi), rng.uniform(0, 2 * np.pi), rng.uniform(1.0, 3.0)
    t = np.arange(n_views) / n_views
    s = ((start + direction * t) % 1.0) * arc[-1]
    xy = np.stack([np.interp(s, arc, closed[:, 0]), np.interp(s, arc, closed[:, 1])], axis=1)
    wobble = rng.normal(0.0, 1.0, (n_views, 3)) * jitter * np.array([1.0, 1.0, 0.5])
    noise = np.deg2rad(rng.normal(0.0, 1.0, (n_views, 3)) * shake_deg)  # heading, pitch, roll
    steady = clearance(xy + wobble[:, :2], size, obstacles) >= min_clearance
    xy = np.where(steady[:, None], xy + wobble[:, :2], xy)
    lo, hi = height_range
    z = np.clip((lo + hi) / 2 + 0.45 * (hi - lo) * np.sin(2 * np.pi * height_cycles * t + height_phase) + wobble[:, 2], lo, hi)

    to_focus = focus - xy
    sweep = np.deg2rad(sweep_deg) * np.sin(2 * np.pi * walk_sweeps(sweeps, n_views) * t + sweep_phase)
    heading = np.arctan2(to_focus[:, 1], to_focus[:, 0]) + sweep + noise[:, 0]
    facing = np.maximum(np.cos(sweep), 0.0)
    pitch_focus = -np.arctan2(z - WALK_FOCUS_HEIGHT, np.linalg.norm(to_focus, axis=1))
    pitch_wall = -np.arctan2(z - WALK_WALL_HEIGHT, WALK_WALL_DISTANCE)
    pitch = facing * pitch_focus + (1 - facing) * pitch_wall + noise[:, 1]
    poses = []
    for i in range(n_views):
        eye = np.array([xy[i, 0], xy[i, 1], z[i]])
        forward = np.array([np.cos(pitch[i]) * np.cos(heading[i]), np.cos(pitch[i]) * np.sin(heading[i]), np.sin(pitch[i])])
        pose = look_at(eye, eye + forward)
        c, s_ = np.cos(noise[i, 2]), np.sin(noise[i, 2])
        pose[:3, :3] = pose[:3, :3] @ np.array([[c, -s_, 0.0], [s_, c, 0.0], [0.0, 0.0, 1.0]])  # roll about the optical axis
        poses.append(pose)
    return np.stack(poses)


def sphere_views(
    target: np.ndarray,
    distance: float,
    azimuths_deg: np.ndarray,
    elevations_deg: np.ndarray,
) -> np.ndarray:
    """Cameras on a sphere around ``target`` (azimuth 0 = looking along +y), looking at it.

    Returns:
        (len(azimuths), 4, 4) camera-to-world poses.
    """
    poses = []
    for az, el in zip(np.deg2rad(azimuths_deg), np.deg2rad(elevations_deg)):
        offset = distance * np.array([np.sin(az) * np.cos(el), -np.cos(az) * np.cos(el), np.sin(el)])
        poses.append(look_at(target + offset, target))
    return np.stack(poses)


def forward_grid(
    centre: np.ndarray,
    grid: tuple[int, int],
    spacing: tuple[float, float],
    look_distance: float,
    rng: np.random.Generator,
    jitter: float = 0.005,
) -> np.ndarray:
    """LLFF-like forward-facing captures: a (cols x rows) planar grid in the x-z plane at ``centre``,
    all cameras looking along +y at a point ``look_distance`` metres ahead (small toe-in).

    Returns:
        (cols * rows, 4, 4) camera-to-world poses, row-major from the top-left of the grid.
    """
    cols, rows = grid
    poses = []
    target = centre + np.array([0.0, look_distance, 0.0])
    for r in range(rows):
        for c in range(cols):
            dx = (c - (cols - 1) / 2) * spacing[0]
            dz = ((rows - 1) / 2 - r) * spacing[1]
            eye = centre + np.array([dx, 0.0, dz]) + rng.normal(0, jitter, 3)
            poses.append(look_at(eye, target))
    return np.stack(poses)


def handheld_forward(
    centre: np.ndarray,
    n_views: int,
    extent: tuple[float, float],
    look_distance: float,
    rng: np.random.Generator,
    rows: int = 3,
    position_jitter: float = 0.1,
    look_jitter_deg: float = 2.0,
) -> np.ndarray:
    """A hand-held forward-facing sweep (LLFF captures: a person moving a phone over a patch in front of
    the scene): ``n_views`` positions on a serpentine over a ``extent = (width, height)`` metre patch of the
    x-z plane at ``centre`` (``rows`` passes, left-right then right-left), each displaced by a Gaussian
    of std ``position_jitter`` x the larger of the row and column spacings (30 % of that along the
    viewing direction, +y), looking along +y at a point ``look_distance``
    ahead, the look-at point jittered by ``look_jitter_deg`` degrees (a hand does not keep aim).

    Frames are in capture order (the LLFF split takes every 8th as a test view, so test views fall
    between training views along the path, as in the real captures).

    Returns:
        (n_views, 4, 4) camera-to-world poses.
    """
    width, height = float(extent[0]), float(extent[1])
    rows = max(1, min(int(rows), n_views))
    per_row = np.full(rows, n_views // rows)
    per_row[: n_views % rows] += 1
    spacing = height / max(rows - 1, 1)
    poses = []
    for r, count in enumerate(per_row):
        xs = np.linspace(-width / 2, width / 2, int(count)) if count > 1 else np.zeros(1)
        if r % 2 == 1:
            xs = xs[::-1]
        z = height / 2 - r * spacing if rows > 1 else 0.0
        for x in xs:
            eye = centre + np.array([x, 0.0, z]) + rng.normal(0.0, position_jitter * max(spacing, width / max(count, 1)), 3) * np.array([1.0, 0.3, 1.0])
            aim = np.deg2rad(look_jitter_deg) * rng.normal(0.0, 1.0, 2)
            target = eye + look_distance * np.array([np.tan(aim[0]), 1.0, np.tan(aim[1])])
            poses.append(look_at(eye, target))
    return np.stack(poses)
