"""Room lighting: point and small area lights with inverse-square fall-off, cast shadows, ambient
occlusion, a constant ambient term and a fixed exposure per scene. Lambertian throughout.

Pixel value of a surface point p (normal n, albedo rho, RGB):

    value = clip(exposure * (rho * (E_direct(p) / pi + A * ao(p)) + L_emit(p)), 0, 1)

* ``E_direct`` (irradiance, relative W/m^2) = sum over lights and their samples s of
  ``I_s(w) max(0, n . w) V_s / r_s^2``: ``w`` the unit direction p -> sample, ``r_s`` its distance,
  ``V_s`` 1 if the shadow ray p -> sample is free (open3d ``RaycastingScene.test_occlusions``).
  A :class:`PointLight` is isotropic (``I_s = I``); an :class:`AreaLight` is a one-sided Lambertian
  emitter (a ceiling light's disc or a window's pane) of on-axis intensity I split over S samples,
  ``I_s = (I / S) max(0, -normal . w)``: several samples give soft shadows.
* ``A`` (radiance per unit albedo) stands for the light that walls, floor and ceiling reflect onto
  each other; ``ao(p)`` in [0, 1] is its ambient occlusion: the cosine-weighted mean over K hemisphere
  rays of ``min(1, t_hit / ao_distance)`` (corners, contact shadows under furniture, the inside of
  shelves get darker; a smooth distance weight instead of a hit / miss count avoids banding).
* ``L_emit``: an emitter's own surface (a ceiling light's diffuser, a window pane) shows its radiance
  ``I / area``; it saturates, as lamps and windows do in real indoor photographs.

View independence: nothing depends on the camera. The sample patterns are fixed (a Vogel spiral on a
light's disc, a grid on a window, a Fibonacci cosine-weighted hemisphere for ambient occlusion), and
the only per-point variation is a rotation of the pattern by a smooth function of the point
(:func:`pattern_angle`: period ~7 cm), which turns the banding of a fixed pattern into a fixed, fine
dither; two views of a point (hit points equal up to float32 rounding, ~1e-6 m) get the same colour.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d
import trimesh

from bench.data.synth.geometry import SceneObject
from bench.data.synth.materials import Textured

GOLDEN_ANGLE = np.pi * (3.0 - np.sqrt(5.0))
SHADOW_OFFSET = 2e-3        # m: shadow / AO rays start this far off the surface (no self-hits)
MIN_LIGHT_DISTANCE = 0.05   # m: r^2 is clamped at this distance (a surface touching a light)
EMITTER_TOLERANCE = 2e-3    # m: points this close to an emitter's plane (inside its outline) glow
# Exposure: the brightest 5 % of an off-white surface (albedo REF_ALBEDO, assumed) on the room's faces and
# on a table-height plane (furniture tops are the surfaces closest to ceiling lights) map to
# EXPOSURE_TARGET, so a room is neither dark nor clipped (auto-exposure of a real camera does the same).
REF_ALBEDO, EXPOSURE_QUANTILE, EXPOSURE_TARGET, TABLE_HEIGHT = 0.8, 0.95, 0.92, 0.75
PATTERN_DIRECTIONS = np.array([[0.83, 0.31, 0.46], [-0.27, 0.88, 0.39], [0.35, -0.41, 0.84]])


def pattern_angle(points: np.ndarray) -> np.ndarray:
    """(M, 3) world points -> (M,) rotation angles (radians) of the sample patterns: a smooth,
    fast-varying function of the point (sum of three oblique sines of period 7 cm, about +-9 rad)."""
    k = 2 * np.pi / 0.07
    return 3.0 * np.sum(np.sin(k * points @ PATTERN_DIRECTIONS.T + np.array([0.0, 1.1, 2.3])), axis=1)


def tangent_frame(normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(M, 3) unit normals -> two (M, 3) unit tangents t, b with (t, b, n) right-handed; a fixed
    function of the normal (helper axis z, or x for near-vertical normals)."""
    helper = np.where(np.abs(normals[:, 2:3]) < 0.9, np.array([[0.0, 0.0, 1.0]]), np.array([[1.0, 0.0, 0.0]]))
    t = np.cross(helper, normals)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    return t, np.cross(normals, t)


def hemisphere_pattern(count: int) -> np.ndarray:
    """(K, 3) cosine-weighted unit directions in a local frame (z = normal): a Fibonacci spiral on the
    unit disc lifted to the hemisphere (Malley's method), so the plain mean over them estimates the
    cosine-weighted integral."""
    k = np.arange(count)
    r = np.sqrt((k + 0.5) / count)
    a = k * GOLDEN_ANGLE
    return np.stack([r * np.cos(a), r * np.sin(a), np.sqrt(1.0 - r**2)], axis=1)


@dataclass(frozen=True)
class PointLight:
    """An isotropic point light at ``position`` (3,) m with RGB radiant intensity ``intensity`` (3,)
    (relative units; the exposure sets the scale)."""

    position: np.ndarray
    intensity: np.ndarray

    def sample(self, points: np.ndarray, angles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Sample positions (M, 1, 3) and their (M, 1) share of ``intensity`` towards each point (1)."""
        m = len(points)
        return np.broadcast_to(self.position, (m, 1, 3)), np.ones((m, 1))

    def emitted(self, points: np.ndarray) -> np.ndarray:
        """A point light has no surface: (M, 3) zeros."""
        return np.zeros((len(points), 3))


@dataclass(frozen=True)
class AreaLight:
    """A one-sided Lambertian emitter centred at ``centre`` (3,) m, emitting towards ``normal`` (3,),
    of on-axis RGB intensity ``intensity`` (3,): a disc of ``radius`` m (``half_extents`` None) or a
    rectangle of ``half_extents`` (a, b) m along ``u_axis`` and ``normal x u_axis``; ``samples`` points
    (a Vogel spiral on the disc, rotated per shaded point; a fixed grid on the rectangle)."""

    centre: np.ndarray
    normal: np.ndarray
    u_axis: np.ndarray
    intensity: np.ndarray
    samples: int
    radius: float = 0.0
    half_extents: tuple[float, float] | None = None

    @property
    def v_axis(self) -> np.ndarray:
        return np.cross(self.normal, self.u_axis)

    @property
    def area(self) -> float:
        if self.half_extents is None:
            return float(np.pi * self.radius**2)
        return float(4.0 * self.half_extents[0] * self.half_extents[1])

    def _local(self, angles: np.ndarray) -> np.ndarray:
        """(M, S, 2) sample coordinates along (u_axis, v_axis), metres."""
        s = self.samples
        if self.half_extents is None:
            j = np.arange(s)
            r = self.radius * np.sqrt((j + 0.5) / s)
            a = j[None, :] * GOLDEN_ANGLE + angles[:, None]
            return np.stack([r[None, :] * np.cos(a), r[None, :] * np.sin(a)], axis=2)
        a, b = self.half_extents
        nu = max(1, int(round(np.sqrt(s * a / b))))
        nv = max(1, int(np.ceil(s / nu)))
        gu, gv = np.meshgrid((np.arange(nu) + 0.5) / nu * 2 - 1, (np.arange(nv) + 0.5) / nv * 2 - 1, indexing="ij")
        grid = np.stack([gu.ravel() * a, gv.ravel() * b], axis=1)[:s]
        return np.broadcast_to(grid, (len(angles), len(grid), 2))

    def sample(self, points: np.ndarray, angles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Sample positions (M, S, 3) and their (M, S) share of ``intensity`` towards each point
        (the emitter's cosine / S)."""
        uv = self._local(angles)
        pos = self.centre + uv[..., :1] * self.u_axis + uv[..., 1:] * self.v_axis
        to_point = points[:, None, :] - pos
        dist = np.sqrt(np.einsum("msk,msk->ms", to_point, to_point))
        cos_l = np.clip((to_point @ self.normal) / np.maximum(dist, 1e-9), 0.0, None)
        return pos, cos_l / uv.shape[1]

    def emitted(self, points: np.ndarray) -> np.ndarray:
        """(M, 3) radiance ``I / area`` on the emitter's surface (within ``EMITTER_TOLERANCE`` of its
        plane and inside its outline), 0 elsewhere."""
        rel = points - self.centre
        u, v, h = rel @ self.u_axis, rel @ self.v_axis, rel @ self.normal
        if self.half_extents is None:
            inside = u**2 + v**2 <= self.radius**2
        else:
            inside = (np.abs(u) <= self.half_extents[0]) & (np.abs(v) <= self.half_extents[1])
        on = inside & (np.abs(h) <= EMITTER_TOLERANCE)
        return on[:, None] * (np.asarray(self.intensity, float) / self.area)[None, :]


Light = PointLight | AreaLight


def _occluded(scene: o3d.t.geometry.RaycastingScene, origins: np.ndarray, directions: np.ndarray, tfar: float) -> np.ndarray:
    """(R,) True where the segment origin + t direction, t in (0, tfar), hits the scene."""
    rays = np.concatenate([origins, directions], axis=1).astype(np.float32)
    return scene.test_occlusions(o3d.core.Tensor(rays), tnear=0.0, tfar=tfar).numpy().astype(bool)


@dataclass(frozen=True)
class RoomLighting:
    """Lights, ambient term, ambient occlusion and exposure of one scene (see the module docstring).

    Attributes:
        lights: the lights.
        ambient: (3,) RGB ambient radiance per unit albedo (relative units, like the lights).
        ao_distance: metres; occluders farther than this do not darken (0 = no ambient occlusion).
        ao_samples: hemisphere rays per shaded point (0 = no ambient occlusion).
        exposure: scale from radiance to pixel value.
        shadows: False skips the shadow rays (every light sample visible).
    """

    lights: tuple[Light, ...]
    ambient: np.ndarray
    ao_distance: float
    ao_samples: int
    exposure: float
    shadows: bool = True

    def irradiance(self, scene: o3d.t.geometry.RaycastingScene | None, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
        """(M, 3) direct irradiance ``E_direct`` at (M, 3) points with (M, 3) unit normals; shadows
        are tested against ``scene`` (None or ``shadows`` False: no shadows)."""
        angles = pattern_angle(points)
        origins = points + SHADOW_OFFSET * normals
        total = np.zeros((len(points), 3))
        for light in self.lights:
            pos, gain = light.sample(points, angles)
            d = pos - points[:, None, :]  # (M, S, 3)
            r2 = np.einsum("msk,msk->ms", d, d)
            cos_r = np.clip(np.einsum("msk,mk->ms", d, normals) / np.sqrt(np.maximum(r2, 1e-18)), 0.0, None)
            weight = gain * cos_r / np.maximum(r2, MIN_LIGHT_DISTANCE**2)  # (M, S)
            if scene is not None and self.shadows:
                m_idx, s_idx = np.nonzero(weight > 0)
                if len(m_idx):  # shadow rays from just off the surface to just before the sample
                    blocked = _occluded(scene, origins[m_idx], pos[m_idx, s_idx] - origins[m_idx], 1.0 - 1e-4)
                    weight[m_idx[blocked], s_idx[blocked]] = 0.0
            total += weight.sum(axis=1)[:, None] * np.asarray(light.intensity, float)[None, :]
        return total

    def ambient_occlusion(self, scene: o3d.t.geometry.RaycastingScene | None, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
        """(M,) ambient visibility in [0, 1] (1 = open; 1 everywhere without a scene or samples)."""
        if scene is None or self.ao_samples == 0 or self.ao_distance <= 0:
            return np.ones(len(points))
        t, b = tangent_frame(normals)
        angles = pattern_angle(points)
        c, s = np.cos(angles)[:, None], np.sin(angles)[:, None]
        t, b = c * t + s * b, c * b - s * t  # the pattern rotated about the normal
        local = hemisphere_pattern(self.ao_samples)  # (K, 3)
        dirs = local[None, :, 0:1] * t[:, None, :] + local[None, :, 1:2] * b[:, None, :] + local[None, :, 2:3] * normals[:, None, :]
        origins = np.broadcast_to((points + SHADOW_OFFSET * normals)[:, None, :], dirs.shape)
        rays = np.concatenate([origins, dirs], axis=2).reshape(-1, 6).astype(np.float32)
        t_hit = scene.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy().reshape(len(points), -1).astype(np.float64)
        return np.mean(np.clip(t_hit / self.ao_distance, 0.0, 1.0), axis=1)

    def emitted(self, points: np.ndarray) -> np.ndarray:
        """(M, 3) radiance emitted by the points (on an emitter's surface), summed over the lights."""
        out = np.zeros((len(points), 3))
        for light in self.lights:
            out += light.emitted(points)
        return out

    def shade(self, scene: o3d.t.geometry.RaycastingScene | None, points: np.ndarray, normals: np.ndarray, albedo: np.ndarray) -> np.ndarray:
        """(M, 3) pixel values in [0, 1] of surface points: (M, 3) world points (m), (M, 3) unit world
        normals (facing the viewer's side of the surface), (M, 3) albedo in [0, 1]."""
        direct = self.irradiance(scene, points, normals) / np.pi
        ambient = self.ambient[None, :] * self.ambient_occlusion(scene, points, normals)[:, None]
        radiance = albedo * (direct + ambient) + self.emitted(points)
        return np.clip(self.exposure * radiance, 0.0, 1.0)


def room_reference_points(size: tuple[float, float, float], per_side: int = 12) -> tuple[np.ndarray, np.ndarray]:
    """A regular grid of points on the six inner faces of the box room [0, sx] x [0, sy] x [0, sz]
    and on the horizontal plane at ``TABLE_HEIGHT`` (facing up), with their normals: (P, 3), (P, 3)
    (P = 7 per_side^2)."""
    g = (np.arange(per_side) + 0.5) / per_side
    a, b = [m.ravel() for m in np.meshgrid(g, g, indexing="ij")]
    sx, sy, sz = size
    pts, nrm = [], []
    for axis, lim in ((0, sx), (1, sy), (2, sz)):
        others = [i for i in range(3) if i != axis]
        for at, sign in ((0.0, 1.0), (lim, -1.0)):
            p = np.zeros((len(a), 3))
            p[:, others[0]] = a * size[others[0]]
            p[:, others[1]] = b * size[others[1]]
            p[:, axis] = at
            n = np.zeros(3)
            n[axis] = sign
            pts.append(p)
            nrm.append(np.broadcast_to(n, p.shape))
    pts.append(np.stack([a * sx, b * sy, np.full_like(a, TABLE_HEIGHT)], axis=1))
    nrm.append(np.broadcast_to(np.array([0.0, 0.0, 1.0]), pts[-1].shape))
    return np.concatenate(pts), np.concatenate(nrm)


def room_lighting(lights: tuple[Light, ...], size: tuple[float, float, float], ambient_fraction: float, ao_distance: float,
                  ao_samples: int) -> RoomLighting:
    """The lighting of a box room. Over the reference points of :func:`room_reference_points` (the
    room's inner faces and a table-height plane), the ambient radiance is ``ambient_fraction`` x the
    mean direct radiance per unit albedo (``E_direct / pi``), and the exposure maps the
    ``EXPOSURE_QUANTILE`` of an albedo-``REF_ALBEDO`` surface's value to ``EXPOSURE_TARGET``. Both come
    from the lights and the room size only (no shadows, no furniture): one exposure per scene, never
    per view."""
    pts, nrm = room_reference_points(size)
    draft = RoomLighting(lights, np.zeros(3), ao_distance, ao_samples, 1.0)
    direct = draft.irradiance(None, pts, nrm) / np.pi  # (P, 3)
    ambient = ambient_fraction * direct.mean(axis=0)
    level = REF_ALBEDO * (direct + ambient[None, :]).mean(axis=1)
    exposure = EXPOSURE_TARGET / max(float(np.quantile(level, EXPOSURE_QUANTILE)), 1e-12)
    return RoomLighting(lights, ambient, ao_distance, ao_samples, exposure)


# Light colours (RGB, mean 1). Assumed: warm-white ceiling lamps (~3500 K), cool daylight through a window.
CEILING_COLOUR = np.array([1.08, 1.0, 0.92])
DAYLIGHT_COLOUR = np.array([0.92, 1.0, 1.08])
FIXTURE_DEPTH = 0.03  # m: a ceiling fixture hangs this far below the ceiling


def ceiling_lights(size: tuple[float, float, float], count: int, radius: float, samples: int,
                   rng: np.random.Generator) -> tuple[list[AreaLight], list[SceneObject]]:
    """``count`` round ceiling lights of ``radius`` m on a grid over the room (cells along the longer
    side first, positions jittered +-10 cm by ``rng``), each an :class:`AreaLight` facing down just
    below a flat fixture (a cylinder ``FIXTURE_DEPTH`` deep, radius + 2 cm, category
    ``ceiling_light``, background: it is flush with the ceiling). Intensity 1 per light (x colour).

    Returns:
        (lights, fixtures).
    """
    sx, sy, sz = size
    cols = max(1, int(round(np.sqrt(count * max(sx, sy) / min(sx, sy)))))
    cols = min(cols, count)
    rows = int(np.ceil(count / cols))
    long_x = sx >= sy
    lights, fixtures = [], []
    for i in range(count):
        r, c = divmod(i, cols)
        n_in_row = min(cols, count - r * cols)
        fa, fb = (c + 0.5) / n_in_row, (r + 0.5) / rows
        fx, fy = (fa, fb) if long_x else (fb, fa)
        x, y = fx * sx + rng.uniform(-0.1, 0.1), fy * sy + rng.uniform(-0.1, 0.1)
        mesh = trimesh.creation.cylinder(radius=radius + 0.02, height=FIXTURE_DEPTH, sections=24)
        mesh.apply_translation([x, y, sz - FIXTURE_DEPTH / 2])
        fixtures.append(SceneObject(f"ceiling_light_{i}", "ceiling_light", mesh, is_background=True, is_thin=False,
                                    albedo=np.array([0.95, 0.95, 0.95]), material=Textured(np.array([0.95, 0.95, 0.95]))))
        lights.append(AreaLight(centre=np.array([x, y, sz - FIXTURE_DEPTH - 5e-4]), normal=np.array([0.0, 0.0, -1.0]),
                                u_axis=np.array([1.0, 0.0, 0.0]), intensity=CEILING_COLOUR.copy(), samples=samples, radius=radius))
    return lights, fixtures
