"""Floor footprints: oriented rectangles on the floor plane (world x, y in metres, z up).

Furniture layout and camera paths reason about the room seen from above: a piece of furniture is the
rectangle its mesh covers on the floor (its local x-y bounds turned by its yaw), a camera keeps a
clearance from every rectangle and from the walls of the room ``[0, sx] x [0, sy]``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
import trimesh


def rotation_2d(yaw: float) -> np.ndarray:
    """(2, 2) rotation of the floor plane by ``yaw`` radians (counter-clockwise seen from above)."""
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s], [s, c]])


@dataclass(frozen=True)
class Footprint:
    """An oriented rectangle on the floor.

    Attributes:
        centre: (2,) world x, y of the rectangle's centre, metres.
        yaw: rotation of the rectangle's own axes from the world axes, radians.
        half: (2,) half extents along the rectangle's own x and y axes, metres.
    """

    centre: np.ndarray
    yaw: float
    half: np.ndarray

    @classmethod
    def of_placed(cls, local: trimesh.Trimesh, x: float, y: float, yaw: float) -> Footprint:
        """The footprint of ``local`` (a mesh in its own frame) once turned by ``yaw`` and moved to (x, y),
        as :func:`bench.data.synth.geometry._place` does."""
        lo, hi = local.bounds[0, :2], local.bounds[1, :2]
        return cls(rotation_2d(yaw) @ ((lo + hi) / 2) + np.array([x, y]), float(yaw), (hi - lo) / 2)

    @classmethod
    def of_mesh(cls, mesh: trimesh.Trimesh) -> Footprint:
        """The axis-aligned footprint of a mesh already in world coordinates."""
        lo, hi = mesh.bounds[0, :2], mesh.bounds[1, :2]
        return cls((lo + hi) / 2, 0.0, (hi - lo) / 2)

    def corners(self) -> np.ndarray:
        """(4, 2) world corners, counter-clockwise."""
        signs = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=float)
        return self.centre + (signs * self.half) @ rotation_2d(self.yaw).T

    def to_local(self, points: np.ndarray) -> np.ndarray:
        """(N, 2) world points in the rectangle's frame (origin at its centre)."""
        d = np.asarray(points, dtype=float) - self.centre
        c, s = np.cos(self.yaw), np.sin(self.yaw)
        return np.stack([d[..., 0] * c + d[..., 1] * s, d[..., 1] * c - d[..., 0] * s], axis=-1)  # R^T d (a (N, 2) @ (2, 2) product is slow)

    def distance(self, points: np.ndarray) -> np.ndarray:
        """(N,) distance in metres from (N, 2) world points to the rectangle (0 inside)."""
        outside = np.maximum(np.abs(self.to_local(points)) - self.half, 0.0)
        return np.linalg.norm(outside, axis=-1)

    def overlaps(self, other: Footprint, gap: float = 0.0) -> bool:
        """Whether the two rectangles come closer than ``gap`` metres (separating-axis test on the
        rectangles grown by ``gap / 2`` each)."""
        a = Footprint(self.centre, self.yaw, self.half + gap / 2)
        b = Footprint(other.centre, other.yaw, other.half + gap / 2)
        ca, cb = a.corners(), b.corners()
        for yaw in (a.yaw, b.yaw):
            for axis in rotation_2d(yaw).T:
                pa, pb = ca @ axis, cb @ axis
                if pa.max() <= pb.min() or pb.max() <= pa.min():
                    return False
        return True

    def bounds(self) -> np.ndarray:
        """(2, 2) world axis-aligned bounds: [[min x, min y], [max x, max y]]."""
        c = self.corners()
        return np.stack([c.min(axis=0), c.max(axis=0)])


def enclosing(footprints: Sequence[Footprint], yaw: float) -> Footprint:
    """The smallest rectangle with axes turned by ``yaw`` that holds every footprint."""
    pts = np.concatenate([f.corners() for f in footprints]) @ rotation_2d(yaw)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    return Footprint(rotation_2d(yaw) @ ((lo + hi) / 2), float(yaw), (hi - lo) / 2)


def clearance(points: np.ndarray, size: Sequence[float], obstacles: Sequence[Footprint]) -> np.ndarray:
    """(N,) free distance in metres around (N, 2) floor points: to the nearest obstacle rectangle or wall
    of the room ``[0, sx] x [0, sy]`` (negative outside the room)."""
    points = np.asarray(points, dtype=float)
    sx, sy = float(size[0]), float(size[1])
    free = np.minimum.reduce([points[:, 0], sx - points[:, 0], points[:, 1], sy - points[:, 1]])
    for f in obstacles:
        free = np.minimum(free, f.distance(points))
    return free
