"""Recipe -> rendered Scene -> effects -> dataset folder in a real on-disk format.

Deterministic: the recipe seed (or an override) seeds independent random streams: geometry and
cameras ``[seed, 0]``, effects ``[seed, 1]``, a room's look (finishes, decor, lights) ``[seed, 3]``;
so adding an effect never moves the furniture, and decor or lights never move the cameras.
The dataset folder is written into a temporary folder and renamed at the end (nothing half-written).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any, cast

import numpy as np
import trimesh

from bench.data.atomic import atomic_directory
from bench.data.datasheet import CARD_NAME, compute_datasheet, write_card
from bench.data.errors import BenchInputError
from bench.data.scene import InstanceInfo, Scene
from bench.data.synth.layouts import build_layout
from bench.data.synth.recipe import SCALES, Recipe, load_recipe, resolve_scale, with_effect_overrides
from bench.data.synth.render import SceneRaycaster
from bench.data.version import __version__


def make_scene(
    recipe: Recipe, scale: str = "small", seed: int | None = None, effect_stream: int | None = None
) -> tuple[Scene, trimesh.Trimesh]:
    """Render ``recipe`` and apply its effects.

    Args:
        recipe: a parsed recipe.
        scale: one of ``SCALES`` (changes views, image size; never the method).
        seed: overrides the recipe's seed when given.
        effect_stream: None (every shipped dataset) = the effects draw from ``default_rng([seed, 1])``;
            an integer k = from ``default_rng([seed, 1, k])``, the same geometry and cameras with an
            independent draw of every effect (a diagnostic: scripts/independent_normal_draw.py).

    Returns:
        (scene, gt_mesh): the Scene with priors after effects, and the GT mesh in world metres.
    """
    from bench.data.synth.effects import apply_effects

    if scale not in SCALES:
        raise BenchInputError(recipe.where(), f"scale must be one of {SCALES}, got {scale!r}")
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int) or seed < 0):
        raise BenchInputError("--seed", f"must be a non-negative integer, got {seed!r}")
    seed = recipe.seed if seed is None else seed
    geom_rng = np.random.default_rng([seed, 0])
    layout = build_layout(recipe, scale, geom_rng, look_rng=np.random.default_rng([seed, 3]))
    if len(layout.poses) == 0:
        raise BenchInputError(recipe.where("cameras"), "recipe yields no cameras")

    raycaster = SceneRaycaster(layout.objects, seed=seed, lighting=layout.lighting)
    views = raycaster.render_all(layout.K, layout.poses, layout.height, layout.width)

    instances = {
        i + 1: InstanceInfo(instance_id=i + 1, name=o.name, category=o.category, is_background=o.is_background, is_thin=o.is_thin)
        for i, o in enumerate(layout.objects)
    }
    seg_background = [
        {int(i): instances[int(i)].is_background for i in np.unique(views.instance[v]) if i != 0} for v in range(len(layout.poses))
    ]
    scene = Scene(
        name=recipe.name,
        kind=recipe.kind,
        source_format=recipe.format,
        images=views.rgb,
        intrinsics=layout.K,
        cam_to_world=layout.poses,
        scale_mat=layout.scale_mat,
        mono_depth=views.depth.copy(),
        mono_normal=views.normal.copy(),
        seg_masks=views.instance.copy(),
        seg_background=seg_background,
        gt_depth=views.depth,
        gt_normal=views.normal,
        gt_instance=views.instance,
        instances=instances,
        splits=layout.splits,
    )
    effect_rng = np.random.default_rng([seed, 1] if effect_stream is None else [seed, 1, effect_stream])
    where = recipe.where("effects")
    effects = [{k: resolve_scale(v, scale, where) for k, v in e.items()} for e in recipe.effects]
    records = apply_effects(scene, effects, effect_rng, where=where)
    scene.images = np.clip(scene.images, 0.0, 1.0).astype(np.float32)
    scene.metadata = {
        "recipe": recipe.raw,
        "recipe_path": str(recipe.path) if recipe.path else None,
        "seed": seed,
        **({} if effect_stream is None else {"effect_stream": effect_stream}),
        "scale": scale,
        "effects": records,
        "layout": layout.info,
        "generator": f"bench {__version__}",
        "convention": "cam_to_world OpenCV (x right, y down, z forward), metres, z-depth",
    }
    gt_mesh = cast(trimesh.Trimesh, trimesh.util.concatenate([o.mesh for o in layout.objects]))
    scene.validate()
    scene.metadata["datasheet"] = compute_datasheet(scene, gt_mesh)  # measured properties (docs/datasheet.md)
    return scene, gt_mesh


def make_dataset(
    recipe_path: str | Path,
    out_dir: str | Path,
    scale: str = "small",
    seed: int | None = None,
    overwrite: bool = False,
    fmt_options: dict[str, Any] | None = None,
    effect_overrides: dict[str, dict[str, Any]] | None = None,
) -> dict[str, Any]:
    """Synthesise the recipe and write it to ``out_dir`` in the recipe's format (atomically).

    ``effect_overrides``: a scene variant, ``{effect name: {parameter: value}}`` (see
    :func:`bench.data.synth.recipe.with_effect_overrides`).

    Returns:
        A summary: ``{"path", "format", "views", "height", "width", "seconds", "bytes"}``.
    """
    from bench.data.formats import write_scene

    t0 = time.perf_counter()
    recipe = with_effect_overrides(load_recipe(recipe_path), effect_overrides)
    scene, gt_mesh = make_scene(recipe, scale=scale, seed=seed)
    options = dict(fmt_options or {})
    if recipe.format == "llff":
        options.setdefault("factors", list(recipe.get("llff", "factors", scale=scale, default=[2])))
    out_dir = Path(out_dir)
    with atomic_directory(out_dir, overwrite=overwrite) as tmp:
        write_scene(scene, tmp, recipe.format, gt_mesh=gt_mesh, **options)
        write_card(scene.metadata["datasheet"], tmp / CARD_NAME)
    size = sum(p.stat().st_size for p in out_dir.rglob("*") if p.is_file())
    return {
        "path": str(out_dir),
        "format": recipe.format,
        "views": scene.num_views,
        "height": scene.height,
        "width": scene.width,
        "seconds": time.perf_counter() - t0,
        "bytes": size,
    }
