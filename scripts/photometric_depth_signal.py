"""How much a dataset's images tell about depth, per surface kind: multi-view photometric residuals.

For pairs of training views (a, b), every pixel of view a is lifted to 3-D with its GT z-depth scaled by
``s`` (s = 1: the true surface; s = 1.03: the surface pushed 3 % away from camera a), projected into
view b, and its colour compared with view b's colour there (bilinear). Pixels count only where view b
sees the same surface point (the TRUE point, s = 1, lands inside view b on the same GT instance within
2 % of view b's GT depth), so every scale is compared on the same pixel set. Output, per surface kind
(wall, floor, ceiling, other = objects and decor): the mean / median / 90th-percentile absolute RGB
difference in 8-bit levels at each scale.

Read it so: at s = 1 the residual is the images' own inconsistency (sensor noise, resampling); the rise
from s = 1 to s = 1.03 is the photometric signal a reconstruction without priors has for putting that
surface at the right depth. A surface whose residual barely rises is one only priors can place.
Lambertian rooms are view-independent, so the rise is texture and shading, nothing else.

Usage:
    .venv/bin/python scripts/photometric_depth_signal.py (RECIPE_NAME | DATASET_DIR) [--scale small]
        [--views 12] [--scales 1.0 1.03]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

KINDS = ("wall", "floor", "ceiling")


def _bilinear(image: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(H, W, 3) image sampled at pixel coordinates u, v (P,) (pixel centres at integers; callers keep
    u in [0, W-1), v in [0, H-1)) -> (P, 3)."""
    u0 = np.floor(u).astype(int)
    v0 = np.floor(v).astype(int)
    fu, fv = (u - u0)[:, None], (v - v0)[:, None]
    return (image[v0, u0] * (1 - fu) * (1 - fv) + image[v0, u0 + 1] * fu * (1 - fv)
            + image[v0 + 1, u0] * (1 - fu) * fv + image[v0 + 1, u0 + 1] * fu * fv)


def pair_residuals(scene, a: int, b: int, scales: list[float]) -> tuple[np.ndarray, dict[float, np.ndarray]]:
    """Residuals of view a's pixels warped into view b.

    Returns:
        (ids, residuals): ids (P,) the GT instance ids of the pixels of view a that view b sees;
        residuals[s] (P,) the mean absolute RGB difference (0-1 units) with view a's depth scaled by s.
    """
    from metrics.camera import backproject, project

    H, W = scene.height, scene.width
    depth_a = scene.gt_depth[a]
    inst_a = scene.gt_instance[a].reshape(-1)
    true_points = backproject(depth_a, scene.intrinsics[a], scene.cam_to_world[a]).reshape(-1, 3)
    u, v, z = project(true_points, scene.intrinsics[b], scene.cam_to_world[b])
    ok = (depth_a.reshape(-1) > 0) & np.isfinite(u) & (u >= 0) & (u < W - 1) & (v >= 0) & (v < H - 1)
    ui = np.round(np.nan_to_num(u)).astype(int).clip(0, W - 1)
    vi = np.round(np.nan_to_num(v)).astype(int).clip(0, H - 1)
    depth_b = scene.gt_depth[b][vi, ui]
    ok &= (np.abs(depth_b - z) < 0.02 * np.abs(z)) & (scene.gt_instance[b][vi, ui] == inst_a)
    colour_a = scene.images[a].reshape(-1, 3)[ok].astype(np.float64)
    out: dict[float, np.ndarray] = {}
    for s in scales:
        pts = backproject(depth_a * s, scene.intrinsics[a], scene.cam_to_world[a]).reshape(-1, 3)[ok]
        us, vs, _ = project(pts, scene.intrinsics[b], scene.cam_to_world[b])
        inside = np.isfinite(us) & (us >= 0) & (us < W - 1) & (vs >= 0) & (vs < H - 1)
        warped = np.full_like(colour_a, np.nan)
        warped[inside] = _bilinear(scene.images[b].astype(np.float64), us[inside], vs[inside])
        out[s] = np.abs(warped - colour_a).mean(axis=1)  # NaN where the pushed point leaves view b
    return inst_a[ok], out


def main() -> None:
    import pandas as pd

    from bench.data.datasets import load_dataset
    from bench.data.formats import load_scene

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scene")
    ap.add_argument("--scale", default="small")
    ap.add_argument("--views", type=int, default=12, help="views spread evenly over the training views; all ordered pairs")
    ap.add_argument("--scales", type=float, nargs="+", default=[1.0, 1.03])
    args = ap.parse_args()

    scene = load_scene(Path(args.scene)) if Path(args.scene).is_dir() else load_dataset(args.scene, args.scale)
    if scene.gt_depth is None or scene.gt_instance is None:
        raise SystemExit(f"{args.scene}: needs GT depth and GT instances")
    views = np.linspace(0, scene.num_views - 1, min(args.views, scene.num_views)).round().astype(int)
    kind_of = {iid: (info.category if info.category in KINDS else "other") for iid, info in scene.instances.items()}
    collected: dict[tuple[str, float], list[np.ndarray]] = {}
    for a in views:
        for b in views:
            if a == b:
                continue
            ids, res = pair_residuals(scene, int(a), int(b), args.scales)
            kinds = np.array([kind_of.get(int(i), "other") for i in ids])
            for s, r in res.items():
                for kind in (*KINDS, "other"):
                    collected.setdefault((kind, s), []).append(r[kinds == kind])
    rows = []
    for (kind, s), parts in collected.items():
        r = np.concatenate(parts) * 255.0
        r = r[np.isfinite(r)]
        if len(r):
            rows.append({"surface": kind, "depth_scale": s, "pixels": len(r), "mean_levels": r.mean(),
                         "median_levels": float(np.median(r)), "p90_levels": float(np.percentile(r, 90))})
    df = pd.DataFrame(rows).sort_values(["surface", "depth_scale"])
    print(f"{scene.name}: {len(views)} views, {len(views) * (len(views) - 1)} ordered pairs; |RGB difference| in 8-bit levels")
    print(df.to_string(index=False, float_format=lambda x: f"{x:.2f}"))


if __name__ == "__main__":
    main()
