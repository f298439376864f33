"""Scene datasets used by jobs: synthesised on first use into a cache folder, then loaded.

A job names a scene by its recipe name (``configs/scenes/<name>.yaml``). The dataset folder is keyed by
recipe name, scale and a hash of the recipe file's content and the code version, so editing a recipe
makes a new dataset and reruns reuse the cached one. Datasets are written atomically, so a crash never
leaves a half-written cache entry.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

from bench import __version__
from bench.errors import BenchInputError
from bench.scene import Scene

REPO_ROOT = Path(__file__).resolve().parent.parent
SCENES_DIR = REPO_ROOT / "configs" / "scenes"
DEFAULT_CACHE = REPO_ROOT / "results" / "cache" / "datasets"


def recipe_path(scene_name: str, scenes_dir: Path = SCENES_DIR) -> Path:
    """Path of the recipe of ``scene_name``; BenchInputError if there is none."""
    path = scenes_dir / f"{scene_name}.yaml"
    if not path.exists():
        known = sorted(p.stem for p in scenes_dir.glob("*.yaml"))
        raise BenchInputError(path, f"no recipe for scene {scene_name!r} (known: {known})")
    return path


def recipe_hash(path: Path) -> str:
    """Short hash of a recipe's bytes and the code version (changes when either changes)."""
    return hashlib.sha256(path.read_bytes() + __version__.encode()).hexdigest()[:10]


def ensure_dataset(scene_name: str, scale: str, cache_dir: Path = DEFAULT_CACHE, scenes_dir: Path = SCENES_DIR) -> Path:
    """Return the dataset folder of ``scene_name`` at ``scale``, synthesising it if not cached."""
    from bench.synth.make import make_dataset

    path = recipe_path(scene_name, scenes_dir)
    out = Path(cache_dir) / f"{scene_name}-{scale}-{recipe_hash(path)}"
    if not out.exists():
        make_dataset(path, out, scale=scale)
    return out


def load_dataset(scene_name: str, scale: str, cache_dir: Path = DEFAULT_CACHE) -> Scene:
    """Synthesise (if needed) and load a scene; LLFF scenes load their ``images_N`` downsampled copy."""
    from bench.formats import load_scene

    from bench.synth.recipe import load_recipe

    folder = ensure_dataset(scene_name, scale, cache_dir)
    recipe = load_recipe(recipe_path(scene_name))
    if recipe.format == "llff":  # the LLFF protocol trains and evaluates on images_N (FSGS: images_8)
        factors = recipe.get("llff", "factors", scale=scale, default=[2])
        return load_scene(folder, factor=int(factors[0]))
    return load_scene(folder)
