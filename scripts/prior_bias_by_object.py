"""Is a scene's monocular depth prior biased per object once it is aligned to GT, and do its normals
face the camera more or less than the GT normals? (docs/studies/base-below-priors-only.md)

For every view, align the mono depth prior to the GT depth with an affine map and report, per GT object,
the median ratio aligned prior / GT depth over all views (< 1: the aligned prior puts the object closer to
the camera than it is). Two alignments:

* ``prior_to_gt``: least squares ``GT ~ a prior + b`` (what the "Priors only" row fuses,
  ``metrics.depth.align_depth``). The prior is the regressor, and its errors (warp, edge bleeding, noise)
  attenuate ``a``, so the aligned depth range is compressed towards the view's mean: far walls come out a
  little closer, near objects a little farther (regression dilution).
* ``gt_to_prior_inverted``: least squares ``prior ~ c GT + d``, then ``(prior - d) / c``: GT is the
  regressor, no attenuation; what remains are the prior's own biases (thin parts pulled to the
  background, bleeding at occlusion edges).

Normals: ``normal_facing_bias_deg``, the median over the object's pixels of (angle between the prior
normal and the direction to the camera) - (the same angle of the GT normal): < 0 means the prior's
surface faces the camera more than it does (e.g. a floor seen at a grazing angle tilted towards the
camera, as a depth compressed towards its mean gives).

Usage:
    .venv/bin/python scripts/prior_bias_by_object.py (RECIPE_NAME | DATASET_DIR) [--scale small]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np


def aligned_ratios(prior: np.ndarray, gt: np.ndarray) -> dict[str, np.ndarray]:
    """(H, W) aligned prior / GT for both alignments over the pixels where both are valid (NaN elsewhere).

    Args:
        prior: (H, W) mono depth prior (any scale), 0 = invalid. gt: (H, W) GT z-depth, metres, 0 = invalid.
    """
    from metrics.depth import align_depth

    valid = (prior > 0) & (gt > 0)
    a, b = align_depth(prior, gt, valid, mode="scale_shift")
    c, d = align_depth(gt, prior, valid, mode="scale_shift")  # prior ~ c GT + d
    safe_gt = np.where(valid, gt, 1.0)
    out = {"prior_to_gt": (a * prior + b) / safe_gt, "gt_to_prior_inverted": ((prior - d) / c) / safe_gt}
    return {k: np.where(valid, v, np.nan) for k, v in out.items()}


def facing_angle_deg(normals: np.ndarray, K: np.ndarray) -> np.ndarray:
    """(H, W) angle (degrees) between camera-frame unit normals (H, W, 3) and the direction from each
    pixel's surface point back to the camera (OpenCV axes, z forward)."""
    from metrics.camera import pixel_rays

    h, w = normals.shape[:2]
    rays = pixel_rays(K, h, w)
    rays = rays / np.linalg.norm(rays, axis=-1, keepdims=True)
    return np.degrees(np.arccos(np.clip(-(normals * rays).sum(-1), -1.0, 1.0)))


def main() -> None:
    import pandas as pd

    from bench.data.datasets import load_dataset
    from bench.data.formats import load_scene

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scene")
    ap.add_argument("--scale", default="small")
    args = ap.parse_args()
    scene = load_scene(Path(args.scene)) if Path(args.scene).is_dir() else load_dataset(args.scene, args.scale)
    if scene.mono_depth is None or scene.gt_depth is None or scene.gt_instance is None:
        raise SystemExit(f"{args.scene}: needs a mono depth prior, GT depth and GT instances")
    per_object: dict[tuple[str, str], list[np.ndarray]] = {}
    for v in range(scene.num_views):
        inst = scene.gt_instance[v]
        maps = aligned_ratios(scene.mono_depth[v].astype(np.float64), scene.gt_depth[v].astype(np.float64))
        if scene.mono_normal is not None and scene.gt_normal is not None:
            K = np.asarray(scene.intrinsics[v], dtype=np.float64)
            has = (np.linalg.norm(scene.mono_normal[v], axis=-1) > 0.5) & (np.linalg.norm(scene.gt_normal[v], axis=-1) > 0.5)
            maps["normal_facing_bias_deg"] = np.where(has, facing_angle_deg(scene.mono_normal[v].astype(np.float64), K)
                                                      - facing_angle_deg(scene.gt_normal[v].astype(np.float64), K), np.nan)
        for column, values in maps.items():  # (H, W), NaN where not measured
            ok = np.isfinite(values)
            for iid in np.unique(inst[ok]):
                info = scene.instances.get(int(iid))
                per_object.setdefault((info.name if info else str(iid), column), []).append(values[ok & (inst == iid)])
    rows = pd.DataFrame([{"object": obj, "column": col, "pixels": int(sum(r.size for r in rs)),
                          "median": float(np.median(np.concatenate(rs)))} for (obj, col), rs in per_object.items()])
    df = rows.pivot(index="object", columns="column", values="median")
    df["pixels"] = rows.query("column == 'prior_to_gt'").set_index("object")["pixels"]
    print(f"{args.scene}: per GT object over {scene.num_views} views, median (aligned prior / GT depth) under both "
          "alignments and the normal prior's facing bias (degrees)")
    print(df.sort_values("pixels", ascending=False).to_string(float_format=lambda x: f"{x:.3f}"))


if __name__ == "__main__":
    main()
