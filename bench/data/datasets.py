"""Scene datasets used by jobs: synthesised on first use into a cache folder, then loaded.

A job names a scene by its recipe name (``configs/scenes/<name>.yaml``) and optionally a scene variant
(``effects``: ``{effect name: {parameter: value}}`` overriding the recipe's effects, e.g. another
simulated prior profile). The dataset folder is keyed by recipe name, scale and a hash of the recipe
file's content, the variant (when it changes anything) and the code version, so editing a recipe
makes a new dataset and reruns reuse the cached one. Datasets are written atomically, so a crash never
leaves a half-written cache entry.

The cache folder is ``results/cache/datasets`` of this checkout, or the folder named by the environment
variable ``BENCH_CACHE`` when it is set (read once, when this module is imported: ``DEFAULT_CACHE`` is the
default argument of the runner, the executors and ``bench.execute``). The test suite points it at a
temporary folder (``tests/conftest.py``) unless it is already exported, so tests never write into
``results/``; export it to keep one cache across test sessions, or to share one cache between checkouts.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import sys
import uuid
from pathlib import Path
from typing import Any, Mapping

from bench.data.errors import BenchInputError
from bench.data.scene import Scene
from bench.data.version import __version__

REPO_ROOT = Path(__file__).resolve().parents[2]  # bench/data/datasets.py -> the repository
SCENES_DIR = REPO_ROOT / "configs" / "scenes"
DEFAULT_CACHE = Path(os.environ["BENCH_CACHE"]).expanduser().absolute() if os.environ.get("BENCH_CACHE") else REPO_ROOT / "results" / "cache" / "datasets"
"""Where datasets are synthesised and cached: ``$BENCH_CACHE`` if set (and not empty), else ``results/cache/datasets``."""


def recipe_path(scene_name: str, scenes_dir: Path = SCENES_DIR) -> Path:
    """Path of the recipe of ``scene_name`` (``configs/scenes/NAME.yaml``; a name may have a sub-folder,
    ``legacy/scannet_like_0``); BenchInputError if there is none."""
    path = scenes_dir / f"{scene_name}.yaml"
    if not path.exists():
        known = sorted(p.stem for p in scenes_dir.glob("*.yaml"))
        raise BenchInputError(path, f"no recipe for scene {scene_name!r} (known: {known})")
    return path


def recipe_hash(path: Path, effects: Mapping[str, Mapping[str, Any]] | None = None) -> str:
    """Short hash of a recipe's bytes and the code version (changes when either changes), and of the
    scene variant ``effects`` when it changes the recipe's effects (a no-op variant, e.g. the profile
    the recipe already uses, hashes like the plain recipe: the same dataset, shared by every table)."""
    data = path.read_bytes() + __version__.encode()
    if effects:
        from bench.data.synth.recipe import load_recipe, with_effect_overrides

        recipe = load_recipe(path)
        variant = with_effect_overrides(recipe, {k: dict(v) for k, v in effects.items()})
        if variant.effects != recipe.effects:
            data += json.dumps(variant.effects, sort_keys=True, default=str).encode()
    return hashlib.sha256(data).hexdigest()[:10]


def is_folder_scene(scene: str) -> bool:
    """True when a table / study names an existing dataset folder instead of a recipe (a user's own data)."""
    return ("/" in scene or scene.startswith(".")) and Path(scene).expanduser().is_dir()


def folder_hash(folder: Path) -> str:
    """Short hash of a dataset folder's files (names and bytes) and the code version: a job on a folder
    reruns when the data changes."""
    h = hashlib.sha256(__version__.encode())
    for p in sorted(Path(folder).rglob("*")):
        if p.is_file() and not p.name.startswith("."):
            h.update(str(p.relative_to(folder)).encode())
            h.update(p.read_bytes())
    return h.hexdigest()[:12]


def scene_hash(scene: str, effects: Mapping[str, Mapping[str, Any]] | None = None) -> str:
    """What a job id covers of its data: the recipe (and variant) hash, or the folder's content hash."""
    if is_folder_scene(scene):
        return folder_hash(Path(scene).expanduser())
    return recipe_hash(recipe_path(scene), effects)


def check_folder_scene(scene: str) -> None:
    """Load a dataset folder a table names as a scene, raising the :class:`BenchInputError` that names its bad
    file: a broken folder stops the run before any job (a recipe scene is checked when it is synthesised)."""
    if is_folder_scene(scene):
        from bench.data.formats import load_scene

        load_scene(Path(scene).expanduser())


def ensure_dataset(scene_name: str, scale: str, cache_dir: Path = DEFAULT_CACHE, scenes_dir: Path = SCENES_DIR,
                   effects: Mapping[str, Mapping[str, Any]] | None = None) -> Path:
    """Return the dataset folder of ``scene_name`` (variant ``effects``) at ``scale``, synthesising it if not
    cached; a dataset folder named as the scene is returned as it is (no variant possible)."""
    from bench.data.synth.make import make_dataset

    if is_folder_scene(scene_name):
        if effects:
            raise BenchInputError(scene_name, "a dataset folder has no recipe: scene variants (effects) need a recipe scene")
        return Path(scene_name).expanduser()

    path = recipe_path(scene_name, scenes_dir)
    # a recipe in a sub-folder of configs/scenes (``legacy/scannet_like_0``) gets a flat cache folder name
    out = Path(cache_dir) / f"{scene_name.replace('/', '--')}-{scale}-{recipe_hash(path, effects)}"
    if not out.exists():
        make_dataset(path, out, scale=scale, effect_overrides={k: dict(v) for k, v in (effects or {}).items()})
    return out


def load_dataset(scene_name: str, scale: str, cache_dir: Path = DEFAULT_CACHE,
                 effects: Mapping[str, Mapping[str, Any]] | None = None) -> Scene:
    """Synthesise (if needed) and load a scene; LLFF scenes load their ``images_N`` downsampled copy."""
    from bench.data.formats import load_scene
    from bench.data.synth.recipe import load_recipe

    if is_folder_scene(scene_name):  # a user's own folder: loaded as it is (LLFF at its full resolution)
        return load_scene(ensure_dataset(scene_name, scale, cache_dir, effects=effects))
    recipe = load_recipe(recipe_path(scene_name))
    options: dict[str, Any] = {"factor": int(recipe.get("llff", "factors", scale=scale, default=[2])[0])} if recipe.format == "llff" else {}
    # (the LLFF protocol trains and evaluates on images_N, FSGS: images_8)
    folder = ensure_dataset(scene_name, scale, cache_dir, effects=effects)
    try:
        return load_scene(folder, **options)
    except BenchInputError as exc:
        # A cached copy the synthesiser wrote is deterministic and was valid: a file in it was damaged
        # since (disk, a user). Move it aside and synthesise it again, once.
        aside = folder.with_name(f".{folder.name}.corrupt-{uuid.uuid4().hex[:8]}")
        try:
            os.replace(folder, aside)
        except FileNotFoundError:  # another worker moved it first
            pass
        print(f"warning: cached dataset {folder} is damaged ({exc}); synthesising it again", file=sys.stderr, flush=True)
        shutil.rmtree(aside, ignore_errors=True)
        return load_scene(ensure_dataset(scene_name, scale, cache_dir, effects=effects), **options)
