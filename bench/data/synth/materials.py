"""Materials: the albedo of a surface as a function of the 3D world point (no UV maps).

A :class:`Material` maps (M, 3) world points (metres) on an object's surface to (M, 3) albedo in
[0, 1]. Legacy objects have no material (their ``albedo`` x ``texture`` is used, see
:class:`bench.data.synth.render.SceneRaycaster`); room finishes and wall decor carry one:

* :class:`Textured`: a base colour times a procedural texture of :mod:`bench.data.synth.shading`.
* :class:`Artwork`: picture-like content on a planar panel (soft colour blobs, bands and strokes on a
  background), in the panel's own 2D coordinates.
* :class:`Parts`: several materials on one object, chosen by axis-aligned boxes (a picture's frame
  and its canvas, a door's panel, frame and handle, the books on a shelf).

Everything is a pure function of the point, so every view of a point agrees on its albedo.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from bench.data.synth.shading import texture_factor


class Material(Protocol):
    """Anything with ``albedo(points (M, 3) world metres) -> (M, 3) RGB in [0, 1]``."""

    def albedo(self, points: np.ndarray) -> np.ndarray: ...


@dataclass(frozen=True)
class Textured:
    """``colour`` (3,) times the texture ``texture`` (period ``scale`` m, ``phase`` rad, ``amplitude``:
    see :func:`bench.data.synth.shading.texture_factor`)."""

    colour: np.ndarray
    texture: str = "none"
    scale: float = 0.2
    phase: float = 0.0
    amplitude: float | None = None

    def albedo(self, points: np.ndarray) -> np.ndarray:
        tex = texture_factor(self.texture, points, self.scale, self.phase, self.amplitude)
        return np.clip(np.asarray(self.colour, float)[None, :] * tex[:, None], 0.0, 1.0)


@dataclass(frozen=True)
class Artwork:
    """Picture-like content on a planar panel.

    Panel coordinates of a point p: ``(u, v) = ((p - origin) . u_axis, (p - origin) . v_axis)`` metres.
    Layers, painted in order over ``background`` (3,):

    * ``bands``: (B,) heights v (m) with (B, 3) colours: above each height, that colour (a landscape's
      ground / horizon / sky), blended over ``band_softness`` m.
    * ``blobs``: (K, 2) centres (u, v) m, (K,) radii m, (K, 3) colours: soft discs (Gaussian weight
      ``exp(-(d / r)^2)``), high contrast against the background.
    * ``strokes``: (S, 2, 2) segment end points (u, v) m, (S,) widths m, (S, 3) colours: marker lines
      with soft edges (a whiteboard's writing, a poster's lines).
    """

    origin: np.ndarray
    u_axis: np.ndarray
    v_axis: np.ndarray
    background: np.ndarray
    bands: np.ndarray = field(default_factory=lambda: np.zeros(0))
    band_colours: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    band_softness: float = 0.03
    blobs: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    blob_radii: np.ndarray = field(default_factory=lambda: np.zeros(0))
    blob_colours: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    strokes: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 2)))
    stroke_widths: np.ndarray = field(default_factory=lambda: np.zeros(0))
    stroke_colours: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))

    def albedo(self, points: np.ndarray) -> np.ndarray:
        rel = points - np.asarray(self.origin, float)[None, :]
        uv = np.stack([rel @ np.asarray(self.u_axis, float), rel @ np.asarray(self.v_axis, float)], axis=1)  # (M, 2)
        out = np.tile(np.asarray(self.background, float), (len(points), 1))
        for height, colour in zip(self.bands, self.band_colours):
            w = np.clip((uv[:, 1] - height) / self.band_softness + 0.5, 0.0, 1.0)
            out = (1 - w)[:, None] * out + w[:, None] * colour[None, :]
        for centre, radius, colour in zip(self.blobs, self.blob_radii, self.blob_colours):
            w = np.exp(-np.sum((uv - centre) ** 2, axis=1) / radius**2)
            out = (1 - w)[:, None] * out + w[:, None] * colour[None, :]
        for (a, b), width, colour in zip(self.strokes, self.stroke_widths, self.stroke_colours):
            ab = b - a
            t = np.clip((uv - a) @ ab / max(float(ab @ ab), 1e-12), 0.0, 1.0)
            dist = np.linalg.norm(uv - (a[None, :] + t[:, None] * ab[None, :]), axis=1)
            w = np.clip(1.0 - (dist - width / 2) / (width / 2), 0.0, 1.0)  # full inside, soft outer half-width
            out = (1 - w)[:, None] * out + w[:, None] * colour[None, :]
        return np.clip(out, 0.0, 1.0)


@dataclass(frozen=True)
class Parts:
    """Several materials on one object: a point takes the material of the first of ``boxes`` (P, 2, 3)
    (world min / max corners, metres, with a 0.1 mm tolerance: surface points lie on box faces) that
    contains it, else ``default``."""

    default: Material
    boxes: np.ndarray
    materials: tuple[Material, ...]
    tolerance: float = 1e-4

    def albedo(self, points: np.ndarray) -> np.ndarray:
        out = np.zeros((len(points), 3))
        todo = np.ones(len(points), dtype=bool)
        for box, material in zip(self.boxes, self.materials):
            inside = todo & np.all((points >= box[0] - self.tolerance) & (points <= box[1] + self.tolerance), axis=1)
            if np.any(inside):
                out[inside] = material.albedo(points[inside])
                todo &= ~inside
        if np.any(todo):
            out[todo] = self.default.albedo(points[todo])
        return out
