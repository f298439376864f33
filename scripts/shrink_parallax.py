"""How far does a uniformly shrunk room move in the training images? (the shrunk-room mode, docs/studies/monosdf-stuck-mode-and-scale-bias.md)

The scale-and-shift-invariant depth loss accepts, for every view at once, a room shrunk by a factor k
about the cameras' centroid c0 (each view's depth becomes nearly an affine map of the true one); the
normal and eikonal terms do not see scale. Only the colour term can object: the shrunk room rendered in
view j shows the texture of the GT point X at pi_j(c0 + k (X - c0)) instead of pi_j(X). This script
measures that displacement in pixels for the GT surface points of the training views, re-projected
into other training views, split by surface class (walls / ceiling are textureless by construction,
floor and objects are textured): the photometric signal that holds the room's scale.

Usage:
    .venv/bin/python scripts/shrink_parallax.py (RECIPE_NAME | DATASET_DIR) [...] [--scale small] [--k 0.95 0.97]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np


def main() -> None:
    import pandas as pd

    from bench.data.datasets import load_dataset
    from bench.data.formats import load_scene
    from metrics.camera import backproject, project

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scenes", nargs="+")
    ap.add_argument("--scale", default="small")
    ap.add_argument("--k", type=float, nargs="+", default=[0.95, 0.97], help="shrink factors")
    ap.add_argument("--ref-stride", type=int, default=4, help="every n-th training view as reference")
    ap.add_argument("--other-stride", type=int, default=3, help="every n-th training view to re-project into")
    args = ap.parse_args()

    rows = []
    for name in args.scenes:
        scene = load_scene(Path(name)) if Path(name).is_dir() else load_dataset(name, args.scale)
        if scene.gt_depth is None or scene.gt_instance is None:
            raise SystemExit(f"{name}: needs GT depth and GT instances")
        views = scene.view_indices("train")
        centres = scene.cam_to_world[views, :3, 3]
        c0 = centres.mean(0)
        background = {i for i, info in scene.instances.items() if info.is_background and info.category != "floor"}
        for k in args.k:
            per_class: dict[str, list[np.ndarray]] = {"walls + ceiling (textureless)": [], "floor + objects (textured)": []}
            for v in views[:: args.ref_stride]:
                valid = (scene.gt_depth[v] > 0).reshape(-1)
                X = backproject(scene.gt_depth[v], scene.intrinsics[v], scene.cam_to_world[v]).reshape(-1, 3)[valid]
                cls = np.isin(scene.gt_instance[v].reshape(-1)[valid], list(background))
                shrunk = c0 + k * (X - c0)
                for j in views[:: args.other_stride]:
                    ua, va, z = project(X, scene.intrinsics[j], scene.cam_to_world[j])
                    ub, vb, _ = project(shrunk, scene.intrinsics[j], scene.cam_to_world[j])
                    a, b = np.stack([ua, va], axis=-1), np.stack([ub, vb], axis=-1)
                    with np.errstate(invalid="ignore"):
                        inside = (z > 0.1) & (ua >= 0) & (ua < scene.width) & (va >= 0) & (va < scene.height)
                    d = np.linalg.norm(a - b, axis=1)
                    per_class["walls + ceiling (textureless)"].append(d[inside & cls])
                    per_class["floor + objects (textured)"].append(d[inside & ~cls])
            for label, parts in per_class.items():
                d = np.concatenate(parts)
                rows.append({"scene": name, "image": f"{scene.width}x{scene.height}",
                             "camera_spread_m": float(np.linalg.norm(centres - c0, axis=1).max()), "k": k, "surface": label,
                             "median_px": float(np.median(d)), "p90_px": float(np.percentile(d, 90)),
                             "share_below_1px": float(np.mean(d < 1.0))})
    with pd.option_context("display.width", 200, "display.max_columns", 20):
        print(pd.DataFrame(rows).round(3).to_string(index=False))


if __name__ == "__main__":
    main()
