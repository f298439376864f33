"""Procedural textures (3D, functions of the world position: no UV maps needed) and Lambertian shading.

Shading here is the legacy one (Lambertian with one directional light plus ambient, no shadows);
rooms with lights, cast shadows and ambient occlusion are shaded by :mod:`bench.data.synth.lighting`.
Both are view-independent, so every view of a surface point agrees on its colour: the multi-view
photometric consistency that neural reconstruction relies on.

Textures ``none`` ... ``grain`` have a fixed amplitude. ``plaster``, ``boards`` and ``carpet`` (the
room finishes of :mod:`bench.data.synth.look`) take an ``amplitude``: the RMS of the relative
albedo modulation (0.03 = the albedo varies by about 3 %), default ``TEXTURE_AMPLITUDE``.
Feature sizes stay at or above ~2 cm, about one pixel at 2-3 m in the small-scale images: the
renderer samples each pixel at its centre, so finer detail would alias into colours that differ
between views (a real sensor averages it away).
"""

from __future__ import annotations

import numpy as np

TEXTURES = ("none", "wood", "tiles", "fabric", "noise", "grain", "plaster", "boards", "carpet")
# RMS relative albedo modulation of the textures that take an amplitude; assumed: painted plaster
# varies by a few % (large plain areas stay plain), floor boards by ~15 % between planks, carpet ~6 %.
TEXTURE_AMPLITUDE = {"plaster": 0.03, "boards": 0.15, "carpet": 0.06}
GRAIN_DIRECTIONS = tuple(v / np.linalg.norm(v) for v in (np.array([1.0, 0.45, 0.7]), np.array([-0.6, 1.0, 0.35]), np.array([0.3, -0.55, 1.0])))
LIGHT_DIR = np.array([0.35, 0.25, 0.90]) / np.linalg.norm([0.35, 0.25, 0.90])
AMBIENT, DIFFUSE = 0.45, 0.55


def texture_factor(name: str, points: np.ndarray, scale: float, phase: float, amplitude: float | None = None) -> np.ndarray:
    """Multiplicative albedo modulation in [~0.6, ~1.1].

    Args:
        name: one of ``TEXTURES``.
        points: (M, 3) world points in metres.
        scale: spatial period in metres.
        phase: per-object phase in radians (makes two objects of a kind differ).
        amplitude: RMS relative modulation of ``plaster`` / ``boards`` / ``carpet`` (None: the
            texture's ``TEXTURE_AMPLITUDE``); the other textures have a fixed amplitude and need None.

    Returns:
        (M,) float64 factors.
    """
    if amplitude is not None and name not in TEXTURE_AMPLITUDE:
        raise ValueError(f"texture {name!r} has a fixed amplitude; only {sorted(TEXTURE_AMPLITUDE)} take one")
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
        return 0.85 + 0.09 * oblique_octaves(points, k, phase, 4, 0.6)
    if name in TEXTURE_AMPLITUDE:
        amp = TEXTURE_AMPLITUDE[name] if amplitude is None else amplitude
        return 1.0 + amp * _FINISHES[name](points, scale, phase)
    raise ValueError(f"unknown texture {name!r}; known: {TEXTURES}")


def oblique_octaves(points: np.ndarray, k: float, phase: float, octaves: int, gain: float) -> np.ndarray:
    """Isotropic detail on any plane: sum over octaves o and the 3 oblique ``GRAIN_DIRECTIONS`` d of
    ``gain**o * sin(k 2**o (p . d) + phase (o + 1) + 1.3 o)``; (M, 3) points -> (M,). Its RMS over a
    large area is ``sqrt(1.5 * sum_o gain**(2 o))`` (independent sines of amplitude a have variance a^2 / 2)."""
    acc = np.zeros(len(points))
    for octave in range(octaves):
        for d in GRAIN_DIRECTIONS:
            acc += (gain**octave) * np.sin((k * 2.0**octave) * (points @ d) + phase * (octave + 1) + 1.3 * octave)
    return acc


def _unit_rms(points: np.ndarray, period: float, phase: float, octaves: int, gain: float) -> np.ndarray:
    """:func:`oblique_octaves` at base ``period`` metres, divided by its RMS (so its RMS is ~1)."""
    rms = np.sqrt(1.5 * sum(gain ** (2 * o) for o in range(octaves)))
    return oblique_octaves(points, 2 * np.pi / max(period, 1e-3), phase, octaves, gain) / rms


def _plaster(points: np.ndarray, scale: float, phase: float) -> np.ndarray:
    """Painted plaster: large, soft mottling (base period ``scale`` m, 3 octaves; 80 % of the variance)
    plus a fine grain (period 4 cm, 2 octaves; 20 %). Unit RMS."""
    return np.sqrt(0.8) * _unit_rms(points, scale, phase, 3, 0.5) + np.sqrt(0.2) * _unit_rms(points, 0.04, phase + 1.0, 2, 0.6)


def _hash01(*ints: np.ndarray) -> np.ndarray:
    """A deterministic pseudo-random value in [0, 1) per integer tuple (the classic sine hash)."""
    acc = np.zeros(np.broadcast(*ints).shape)
    for i, v in enumerate(ints):
        acc = acc + v * (12.9898 + 65.233 * i)
    return np.modf(np.abs(np.sin(acc) * 43758.5453))[0]


def _boards(points: np.ndarray, scale: float, phase: float) -> np.ndarray:
    """Floor boards along x: planks ``scale`` m wide and 8 x as long, ends staggered row by row; each
    plank its own shade (uniform in [-1, 1]), a soft grain along the plank, and edges darkening over
    the last 1.5 cm (bevels: a 2 mm seam itself would alias at these resolutions). Unit RMS
    (approximately: the plank shades dominate)."""
    x, y = points[:, 0], points[:, 1]
    length = 8.0 * scale
    row = np.floor(y / scale)
    shifted = x + length * _hash01(row, np.full_like(row, phase))
    col = np.floor(shifted / length)
    plank = 2.0 * _hash01(row, col) - 1.0
    grain = np.sin(2 * np.pi * (y / (0.3 * scale)) + 3.0 * np.sin(2 * np.pi * x / length + 7.0 * plank) + phase)
    fy, fx = (y / scale) % 1.0 * scale, (shifted / length) % 1.0 * length  # m into the plank
    edge = np.minimum(np.minimum(fy, scale - fy), np.minimum(fx, length - fx))
    bevel = np.clip(1.0 - edge / 0.015, 0.0, 1.0)
    return np.sqrt(3.0) * (0.9 * plank + 0.25 * grain) - 1.5 * bevel


def _carpet(points: np.ndarray, scale: float, phase: float) -> np.ndarray:
    """Carpet: a fine pile pattern (period ``scale`` m and 1.7 x ``scale`` at another phase, so it is
    not one regular weave; 60 % of the variance) over faint large blotches (period 0.6 m, 40 %). Unit RMS."""
    fine = (_unit_rms(points, scale, phase, 1, 1.0) + _unit_rms(points, 1.7 * scale, phase + 4.0, 1, 1.0)) / np.sqrt(2.0)
    return np.sqrt(0.6) * fine + np.sqrt(0.4) * _unit_rms(points, 0.6, phase + 2.0, 2, 0.5)


_FINISHES = {"plaster": _plaster, "boards": _boards, "carpet": _carpet}


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
