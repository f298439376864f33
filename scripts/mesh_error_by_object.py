"""Where a reconstructed mesh is wrong: its ray-cast depth against the GT depth, per GT object.

For every view of a dataset (or every ``--stride``-th), ray-cast the mesh (world metres) at the view's
camera, compare with the GT z-depth pixel by pixel, and group the pixels by their GT instance: per
object the pixel count, the median |error| (m), the fraction of pixels off by more than 5 cm and by more
than 30 cm, and the fraction where the mesh is in front of GT (a surface where there is none) vs behind
(a surface missing), and the median ratio mesh depth / GT depth (< 1 on every large surface: a room
shrunk towards the cameras). Also an image of the error maps of a few views (``--png``).

Usage:
    .venv/bin/python scripts/mesh_error_by_object.py MESH.ply (RECIPE_NAME | DATASET_DIR) [--scale small]
        [--stride 4] [--png errors.png]

A study writes every snapshot mesh of every run to ``<out>/meshes/`` (``bench study convergence``).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np


def main() -> None:
    import pandas as pd
    import trimesh

    from bench.data.datasets import load_dataset
    from bench.data.formats import load_scene
    from metrics.render import render_depth_maps

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("mesh")
    ap.add_argument("scene")
    ap.add_argument("--scale", default="small")
    ap.add_argument("--stride", type=int, default=4, help="every stride-th view")
    ap.add_argument("--png", default=None)
    args = ap.parse_args()

    scene = load_scene(Path(args.scene)) if Path(args.scene).is_dir() else load_dataset(args.scene, args.scale)
    if scene.gt_depth is None or scene.gt_instance is None:
        raise SystemExit(f"{args.scene}: needs GT depth and GT instances")
    mesh = trimesh.load(args.mesh, force="mesh", process=False)
    views = np.arange(0, scene.num_views, max(1, args.stride))
    depth = render_depth_maps(mesh, scene.intrinsics[views], scene.cam_to_world[views], scene.height, scene.width)
    gt, inst = scene.gt_depth[views], scene.gt_instance[views]
    valid = gt > 0
    err = np.where(valid & (depth > 0), depth - gt, np.where(valid, np.inf, 0.0))  # inf: the mesh has no surface there
    rows = []
    for iid in np.unique(inst[valid]):
        m = valid & (inst == iid)
        e = err[m]
        info = scene.instances.get(int(iid))
        a = np.abs(e)
        rows.append({"object": info.name if info else str(iid), "thin": bool(info and info.is_thin), "pixels": int(m.sum()),
                     "median_err_m": float(np.median(a)), "frac_gt_5cm": float((a > 0.05).mean()),
                     "frac_gt_30cm": float((a > 0.30).mean()), "frac_in_front": float((e < -0.05).mean()),
                     "frac_behind_or_missing": float((e > 0.05).mean()),
                     # < 1 on every large surface: a room shrunk towards the cameras (the scale-and-shift ambiguity)
                     "depth_ratio_median": float(np.median(depth[m & (depth > 0)] / gt[m & (depth > 0)])) if (m & (depth > 0)).any() else float("nan")})
    df = pd.DataFrame(rows).sort_values("pixels", ascending=False)
    a = np.abs(err[valid])
    print(f"{args.mesh} on {scene.name}: {len(views)} views, {valid.sum()} GT pixels; median |err| {np.median(a):.3f} m, "
          f"> 5 cm {np.mean(a > 0.05):.3f}, > 30 cm {np.mean(a > 0.30):.3f}, no surface {np.mean(~np.isfinite(a)):.3f}")
    print(df.to_string(index=False, float_format=lambda v: f"{v:.3f}"))
    if args.png:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        k = min(4, len(views))
        fig, ax = plt.subplots(3, k, figsize=(3 * k, 6.5), squeeze=False)
        for j in range(k):
            i = int(views[j * len(views) // k])
            jj = j * len(views) // k
            ax[0, j].imshow(scene.images[i])
            ax[0, j].set_title(f"view {i}")
            ax[1, j].imshow(np.where(valid[jj], np.clip(np.abs(err[jj]), 0, 0.3), np.nan), cmap="magma", vmin=0, vmax=0.3)
            ax[1, j].set_title("|mesh - GT| depth (0-30 cm)")
            ax[2, j].imshow(np.where(valid[jj], np.clip(np.nan_to_num(err[jj], posinf=0.3), -0.3, 0.3), np.nan), cmap="coolwarm",
                            vmin=-0.3, vmax=0.3)
            ax[2, j].set_title("signed: blue = in front")
            for r in range(3):
                ax[r, j].axis("off")
        fig.tight_layout()
        fig.savefig(args.png, dpi=80)
        print(f"wrote {args.png}")


if __name__ == "__main__":
    main()
