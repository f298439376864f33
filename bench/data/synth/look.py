"""The look of a room: surface finishes, wall decor and lights (the recipe's ``look:`` section,
:class:`bench.data.synth.recipe.LookSection`, over the room preset's values).

:func:`dress_room` takes the bare shell of :func:`bench.data.synth.geometry.build_room_shell` and
returns it finished (plaster walls and ceiling, floor boards or carpet), plus the decor
(:mod:`bench.data.synth.decor`), the ceiling-light fixtures, the floor boxes furniture must leave
clear and the :class:`bench.data.synth.lighting.RoomLighting` (None = the legacy directional shading).
Every random draw comes from the generator passed in (the scene's look stream), so switching the look
on or off moves neither the cameras nor the furniture (apart from furniture that a door's or a wall
shelf's keep-clear box now rejects). With the legacy look (decor none, wall finish none, floor
tiles, directional lighting) nothing is drawn and nothing is changed.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from bench.data.synth.decor import build_decor
from bench.data.synth.geometry import SceneObject
from bench.data.synth.lighting import DAYLIGHT_COLOUR, AreaLight, Light, RoomLighting, ceiling_lights, room_lighting
from bench.data.synth.materials import Textured
from bench.data.synth.recipe import LookSection

CEILING_PLASTER_RATIO = 1.0 / 3.0  # assumed: a ceiling is plainer than the walls (rolled paint, no hand marks)


@dataclass
class Dressing:
    """A dressed room.

    Attributes:
        objects: the shell (finished), then the decor, then the ceiling-light fixtures.
        keep_clear: (2, 2) xy min / max floor boxes furniture must avoid.
        lighting: the room's lighting, or None for the legacy directional shading.
        info: what was built (recorded in the dataset metadata).
    """

    objects: list[SceneObject]
    keep_clear: list[np.ndarray] = field(default_factory=list)
    lighting: RoomLighting | None = None
    info: dict[str, Any] = field(default_factory=dict)


def _finish(obj: SceneObject, look: LookSection, rng: np.random.Generator) -> SceneObject:
    """The shell object ``obj`` with the look's finish (unchanged if its finish is the legacy one)."""
    if obj.category == "wall" and look.wall_finish == "plaster":
        return dataclasses.replace(obj, material=Textured(obj.albedo, "plaster", float(rng.uniform(0.6, 1.0)), float(rng.uniform(0, 2 * np.pi)),
                                                          look.plaster_amplitude))
    if obj.category == "ceiling" and look.wall_finish == "plaster":
        return dataclasses.replace(obj, material=Textured(obj.albedo, "plaster", 1.0, float(rng.uniform(0, 2 * np.pi)),
                                                          look.plaster_amplitude * CEILING_PLASTER_RATIO))
    if obj.category == "floor" and look.floor_finish == "boards":  # oak-ish planks 12-20 cm wide
        colour = np.clip(np.array([0.55, 0.40, 0.26]) + rng.uniform(-0.08, 0.08, 3), 0.05, 0.95)
        return dataclasses.replace(obj, albedo=colour, material=Textured(colour, "boards", float(rng.uniform(0.12, 0.2)), float(rng.uniform(0, 100))))
    if obj.category == "floor" and look.floor_finish == "carpet":  # muted grey / blue / beige office carpet
        colour = np.clip(np.array([0.42, 0.42, 0.42]) + rng.uniform(-0.1, 0.1, 3), 0.05, 0.95)
        return dataclasses.replace(obj, albedo=colour, material=Textured(colour, "carpet", float(rng.uniform(0.04, 0.07)), float(rng.uniform(0, 2 * np.pi))))
    return obj


def dress_room(shell: list[SceneObject], size: tuple[float, float, float], look: LookSection, rng: np.random.Generator,
               obstacles: Sequence[np.ndarray] = ()) -> Dressing:
    """Finish the shell of the box room of ``size`` (sx, sy, sz) m, add the decor and the lights of
    ``look``, drawing from ``rng`` (draw order: finishes, decor, lights). ``obstacles``: (2, 3) world
    min / max boxes of furniture already standing in the room; no decor is hung on the wall span behind
    one (below its top), and no door opens onto one (:func:`bench.data.synth.decor.build_decor`)."""
    objects = [_finish(o, look, rng) for o in shell]
    decor = build_decor(size, look.decor, rng, obstacles)
    objects += decor.objects
    info: dict[str, Any] = {**dataclasses.asdict(look), "decor_items": decor.info}
    if look.lighting == "directional":
        return Dressing(objects, decor.keep_clear, None, info)
    lights: list[Light] = []
    ceiling, fixtures = ceiling_lights(size, look.ceiling_lights, look.light_radius, look.shadow_samples, rng)
    lights += ceiling
    objects += fixtures
    if look.window_light:
        lights += [AreaLight(p.centre, p.normal, p.u_axis, DAYLIGHT_COLOUR * look.window_intensity, look.shadow_samples, half_extents=p.half_extents)
                   for p in decor.panes]
    lighting = room_lighting(tuple(lights), size, look.ambient, look.ao_distance, look.ao_samples)
    info.update(window_lights=len(lights) - len(ceiling), exposure=lighting.exposure, ambient_rgb=lighting.ambient.tolist())
    return Dressing(objects, decor.keep_clear, lighting, info)
