"""DIAGNOSTIC dataset (docs/studies/normal-prior-independent-errors.md): a scene's depth prior with a normal prior from an independent draw of the
same prior-error process.

The legacy profiles (``*-legacy``) compute the normal prior from the perturbed depth prior (``normal_from_depth``
at the end of the chain), so every random depth error of a view (its low-frequency warp, which thin parts vanish,
how far they are pulled, the noise) is also in that view's normals; the calibrated profiles already draw their
normal errors apart from the depth's (``normal_network``), for them this only redraws both. This script writes a copy of the recipe's dataset
whose files are byte-identical to ``bench scenes make RECIPE`` except ``*_normal.npy`` (and ``meta.json``):
those come from the same recipe made again with another random stream for its effects
(``make_scene(..., effect_stream=draw)``: ``default_rng([seed, 1, draw])``; the shipped scene uses ``[seed, 1]``). The normal errors
then have the same character and the same deterministic regions (edges, thin parts: both chains see the GT
geometry), but the random part of them is drawn independently of the depth prior's.

The question it answers: does the base fail on the shipped priors because the normal prior's errors are the
depth prior's own (the two priors agree on each view's error), or because of the normal errors as such?

Usage:
    .venv/bin/python scripts/independent_normal_draw.py RECIPE --out DIR [--scale small] [--draw 1]
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np


def independent_normals(recipe_ref: str, scale: str, draw: int) -> tuple[Any, Any, np.ndarray]:
    """(shipped scene, GT mesh, (N, H, W, 3) camera-frame unit normal prior of the same recipe made with the
    independent effect stream ``[seed, 1, draw]``; 0 = invalid).

    Args:
        recipe_ref: a recipe name (configs/scenes) or a recipe file. scale: the scale preset. draw: >= 1.
    """
    from bench.data.datasets import recipe_path
    from bench.data.synth.make import make_scene
    from bench.data.synth.recipe import load_recipe

    if draw < 1:
        raise SystemExit("--draw must be >= 1")
    path = Path(recipe_ref) if recipe_ref.endswith((".yaml", ".yml")) else recipe_path(recipe_ref)
    recipe = load_recipe(path)
    scene, gt_mesh = make_scene(recipe, scale=scale)
    other, _ = make_scene(recipe, scale=scale, effect_stream=draw)
    return scene, gt_mesh, np.asarray(other.mono_normal)


def main() -> None:
    from bench.data.atomic import atomic_directory
    from bench.data.formats import write_scene

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("recipe")
    ap.add_argument("--out", required=True, type=Path)
    ap.add_argument("--scale", default="small")
    ap.add_argument("--draw", type=int, default=1, help="index of the independent random stream (>= 1)")
    args = ap.parse_args()
    scene, gt_mesh, normals = independent_normals(args.recipe, args.scale, args.draw)
    shipped = np.asarray(scene.mono_normal)
    scene.mono_normal = normals.astype(np.float32)
    scene.metadata = dict(scene.metadata, diagnostic=f"normal prior from an independent draw {args.draw} "
                          "of the recipe's effect chain (scripts/independent_normal_draw.py)")
    with atomic_directory(args.out) as tmp:
        write_scene(scene, tmp, scene.source_format, gt_mesh=gt_mesh)
    valid = (np.linalg.norm(shipped, axis=-1) > 0.5) & (np.linalg.norm(normals, axis=-1) > 0.5)
    cos = np.clip((shipped[valid] * normals[valid]).sum(-1), -1.0, 1.0)
    print(f"wrote {args.out}: angle between the shipped and the independent normal prior: median "
          f"{np.degrees(np.median(np.arccos(cos))):.1f} deg over {int(valid.sum())} pixels")


if __name__ == "__main__":
    main()
