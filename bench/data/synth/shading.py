"""Procedural textures (3D, functions of the world position: no UV maps needed) and Lambertian shading.

Shading is view-independent (Lambertian with one directional light plus ambient), so every view of a
surface point agrees on its colour: the multi-view photometric consistency that neural reconstruction
relies on. Textureless walls and ceilings are kept on purpose.
"""

from __future__ import annotations

import numpy as np

TEXTURES = ("none", "wood", "tiles", "fabric", "noise", "grain")
GRAIN_DIRECTIONS = tuple(v / np.linalg.norm(v) for v in (np.array([1.0, 0.45, 0.7]), np.array([-0.6, 1.0, 0.35]), np.array([0.3, -0.55, 1.0])))
LIGHT_DIR = np.array([0.35, 0.25, 0.90]) / np.linalg.norm([0.35, 0.25, 0.90])
AMBIENT, DIFFUSE = 0.45, 0.55


def texture_factor(name: str, points: np.ndarray, scale: float, phase: float) -> np.ndarray:
    """Multiplicative albedo modulation in [~0.6, ~1.1].

    Args:
        name: one of ``TEXTURES``.
        points: (M, 3) world points in metres.
        scale: spatial period in metres.
        phase: per-object phase in radians (makes two objects of a kind differ).

    Returns:
        (M,) float64 factors.
    """
    x, y, z = points[:, 0], points[:, 1], points[:, 2]
    k = 2 * np.pi / max(scale, 1e-3)
    if name == "none":
        return np.ones(len(points))
    if name == "wood":
        ring = np.sin(k * (x + 0.3 * y) + 2.0 * np.sin(0.5 * k * z + phase) + phase)
        return 0.85 + 0.15 * ring
    if name == "tiles":
        u, v = np.floor(x / scale), np.floor(y / scale)
        checker = ((u + v) % 2) * 0.12
        gu, gv = (x / scale) % 1.0, (y / scale) % 1.0
        grout = ((gu < 0.03) | (gv < 0.03)) * 0.3
        return 0.95 - checker - grout
    if name == "fabric":
        return 0.88 + 0.12 * np.sin(3 * k * x + phase) * np.sin(3 * k * y + 1.3 * phase) * np.sin(3 * k * z)
    if name == "noise":
        acc = np.zeros(len(points))
        for octave in range(3):
            f = k * (2.0**octave)
            acc += (0.5**octave) * np.sin(f * x + phase * (octave + 1)) * np.sin(f * y + 0.7 * phase) * np.sin(f * z + 1.7)
        return 0.85 + 0.18 * acc
    if name == "grain":  # fine isotropic detail on any plane: sines along 3 oblique directions per octave
        acc = np.zeros(len(points))
        for octave in range(4):
            for d in GRAIN_DIRECTIONS:
                acc += (0.6**octave) * np.sin((k * 2.0**octave) * (points @ d) + phase * (octave + 1) + 1.3 * octave)
        return 0.85 + 0.09 * acc
    raise ValueError(f"unknown texture {name!r}; known: {TEXTURES}")


def shade(albedo: np.ndarray, normals_world: np.ndarray) -> np.ndarray:
    """Lambertian shading: albedo * (ambient + diffuse * |n . l|).

    Args:
        albedo: (M, 3) in [0, 1].
        normals_world: (M, 3) unit normals (world frame).

    Returns:
        (M, 3) float64 RGB clipped to [0, 1].
    """
    lambert = np.abs(normals_world @ LIGHT_DIR)
    return np.clip(albedo * (AMBIENT + DIFFUSE * lambert)[:, None], 0.0, 1.0)
