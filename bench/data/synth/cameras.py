"""Camera placement: look-at poses (OpenCV axes) and the paths of the three scene kinds.

All poses are (4, 4) float64 camera-to-world matrices, OpenCV axes (x right, y down, z forward),
world z up, metres.
"""

from __future__ import annotations

import numpy as np

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
