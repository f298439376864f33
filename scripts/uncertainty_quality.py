"""MonoInstance's uncertainty stage with a perfect stage 1 (reference = GT depth) on shipped scenes: the
association and uncertainty quality it reaches (``methods.monoinstance.stage.stage_quality``), one line
per scene. Usage: ``python scripts/uncertainty_quality.py scannet_like_0:small legacy/scannet_like_tiny:tiny``."""

from __future__ import annotations

import argparse

from bench.data.datasets import load_dataset
from methods.monoinstance.stage import run_uncertainty_stage

KEYS = ("assoc_ari", "assoc_ari_fg", "assoc_purity", "seg_ari_per_view", "unc_spearman", "unc_mean_thin", "unc_mean_planar",
        "err_mean_thin", "err_mean_planar")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="+", metavar="NAME:SCALE", help="a scene recipe name and a scale (default small)")
    parser.add_argument("--seed", type=int, default=0, help="the stage's rng seed")
    args = parser.parse_args()
    for item in args.scenes:
        name, _, scale = item.partition(":")
        scene = load_dataset(name, scale or "small")
        quality = run_uncertainty_stage(scene, scene.gt_depth, {}, rng_seed=args.seed).quality
        print(f"{name} ({scale or 'small'}): " + " ".join(f"{k} {quality[k]:.3f}" for k in KEYS), flush=True)


if __name__ == "__main__":
    main()
