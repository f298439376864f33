"""What makes a sparse-view (LLFF-like) scene discriminative, measured before any method row is compared.

Per scene (and per seed for the trained part):

* ``unseen_frac``: fraction of the test pixels (with GT depth) seen by fewer than 2 training views. A
  test pixel is back-projected with its GT z-depth and projected into each training view; it counts as
  seen there if it lands inside the image and in front of (or on) that view's GT surface (its z within
  ``max(3 cm, 2 %)`` of the GT depth at the nearest pixel: not occluded). Pure geometry, no method.
* ``disparity_px``: median over test pixels of the largest pixel displacement between the test view and
  the training views (how far the novel views are from the training views, in pixels).
* 3DGS (the ``gs3d`` config at ``--scale``, ``--set`` overrides), per seed and snapshot: PSNR on the
  3 training views and on the test views and their **gap** (few-shot overfitting: a gap near 0 means the
  test views are as easy as the training views and a depth prior has nothing to correct), and the
  median |rendered depth - GT depth| on the test views (m; pixels where the render covers alpha >= 0.5),
  i.e. against the oracle depth.

Usage:
    .venv/bin/python scripts/fewshot_properties.py SCENE [SCENE ...] [--scale small] [--seeds 0 1 2]
        [--set iterations=3000 ...] [--out results/runs/fewshot_properties]
    .venv/bin/python scripts/fewshot_properties.py SCENE [SCENE ...] --rows results/runs
        (no training: the 3DGS rows a ``bench run --table llff --out results/runs`` stored, i.e. their
        ``extra.train_psnr``, test PSNR curve and ``artifacts/<job>/depths.npy``)

Writes ``properties.csv`` (one row per scene x seed x snapshot) and ``properties.md`` (the final
snapshot per scene: mean over seeds) in ``--out``; prints the table.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np


def coverage_of_test_views(scene) -> tuple[float, float]:
    """(fraction of test pixels seen by < 2 training views, median max disparity in px) from GT depth."""
    from metrics.camera import backproject

    train, test = scene.view_indices("train"), scene.view_indices("test")
    H, W = scene.height, scene.width
    seen_counts, disparities = [], []
    vv, uu = np.meshgrid(np.arange(H), np.arange(W), indexing="ij")
    for t in test:
        valid = scene.gt_depth[t] > 0
        pix = np.stack([uu[valid], vv[valid]], 0).astype(np.float64)
        world = backproject(scene.gt_depth[t], scene.intrinsics[t], scene.cam_to_world[t])[valid].T  # (3, M)
        count = np.zeros(valid.sum(), dtype=int)
        max_disp = np.zeros(valid.sum())
        for v in train:
            w2c = np.linalg.inv(scene.cam_to_world[v])
            pc = w2c[:3, :3] @ world + w2c[:3, 3:4]
            zc = pc[2]
            uvw = scene.intrinsics[v] @ pc
            u, w_ = uvw[0] / np.maximum(zc, 1e-9), uvw[1] / np.maximum(zc, 1e-9)
            ui, vi = np.round(u).astype(int), np.round(w_).astype(int)
            inside = (zc > 0) & (ui >= 0) & (ui < W) & (vi >= 0) & (vi < H)
            gt_there = np.zeros_like(zc)
            gt_there[inside] = scene.gt_depth[v][vi[inside], ui[inside]]
            tol = np.maximum(0.03, 0.02 * zc)
            visible = inside & (gt_there > 0) & (zc <= gt_there + tol)
            count += visible
            disp = np.hypot(u - pix[0], w_ - pix[1])
            max_disp = np.maximum(max_disp, np.where(inside, disp, 0.0))
        seen_counts.append(count)
        disparities.append(max_disp)
    counts = np.concatenate(seen_counts)
    return float((counts < 2).mean()), float(np.median(np.concatenate(disparities)))


def median_depth_error(depths: np.ndarray | None, gt: np.ndarray) -> float:
    """Median |rendered z-depth - GT z-depth| (m) where both are > 0; NaN without a rendered depth."""
    if depths is None:
        return float("nan")
    ok = (depths > 0) & (gt > 0)
    return float(np.median(np.abs(depths[ok] - gt[ok]))) if ok.any() else float("nan")


def _rows_from_table(root: Path, scale: str, method: str, name: str, scene, unseen: float, disp: float) -> list[dict]:
    """Property rows from stored result rows (``root/scale/jobs/*.json``) of ``method`` on scene ``name``."""
    import json

    test = scene.view_indices("test")
    out = []
    for f in sorted((root / scale / "jobs").glob("*.json")):
        row = json.loads(f.read_text())
        if row.get("method") != method or row.get("scene") != name or row.get("status") != "ok":
            continue
        train_psnr = (row.get("extra") or {}).get("train_psnr") or []
        depth_file = root / scale / "artifacts" / row["job_id"] / "depths.npy"
        derr = median_depth_error(np.load(depth_file) if depth_file.exists() else None, scene.gt_depth[test])
        for k, point in enumerate(row["curve"]):
            tp = train_psnr[k] if k < len(train_psnr) else float("nan")
            last = k == len(row["curve"]) - 1
            out.append({"scene": name, "seed": row["seed"], "iterations": point["iterations"], "fraction": point["fraction"],
                        "train_psnr": tp, "test_psnr": point["metrics"]["psnr"], "gap_db": tp - point["metrics"]["psnr"],
                        "test_depth_err_m": derr if last else float("nan"), "unseen_frac": unseen, "disparity_px": disp,
                        "seconds": row.get("wall_seconds", float("nan"))})
    if not out:
        raise SystemExit(f"{root / scale / 'jobs'}: no stored {method} row on {name}")
    return out


def main() -> None:
    import pandas as pd

    from bench.data.datasets import load_dataset
    from bench.evaluate import evaluate_snapshot
    from bench.overrides import parse_overrides
    from methods.registry import get_method, method_config

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scenes", nargs="+")
    ap.add_argument("--scale", default="small")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--method", default="gs3d")
    ap.add_argument("--set", nargs="+", default=[], metavar="KEY=VALUE")
    ap.add_argument("--out", default="results/runs/fewshot_properties")
    ap.add_argument("--rows", default=None, help="read the 3DGS rows of a `bench run --out` folder instead of training")
    args = ap.parse_args()

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for name in args.scenes:
        scene = load_dataset(name, args.scale)
        unseen, disp = coverage_of_test_views(scene)
        test = scene.view_indices("test")
        print(f"[{name}] {scene.num_views} views, train {scene.view_indices('train').tolist()}, test {test.tolist()}: "
              f"test pixels seen by < 2 training views {unseen:.3f}, median max disparity {disp:.1f} px", flush=True)
        if args.rows:
            rows.extend(_rows_from_table(Path(args.rows), args.scale, args.method, name, scene, unseen, disp))
            continue
        cfg = method_config(args.method, args.scale, parse_overrides(args.set))
        for seed in args.seeds:
            t0 = time.perf_counter()
            art = get_method(args.method).fit(scene, cfg, seed)
            for snap, train_psnr in zip(art.snapshots, art.extra.get("train_psnr", [np.nan] * len(art.snapshots))):
                test_psnr = evaluate_snapshot(snap, scene, "llff", args.scale, seed)["psnr"]
                derr = median_depth_error(snap.depths, scene.gt_depth[test])
                rows.append({"scene": name, "seed": seed, "iterations": snap.iterations, "fraction": snap.fraction,
                             "train_psnr": train_psnr, "test_psnr": test_psnr, "gap_db": train_psnr - test_psnr,
                             "test_depth_err_m": derr, "unseen_frac": unseen, "disparity_px": disp,
                             "seconds": time.perf_counter() - t0})
            last = rows[-1]
            print(f"[{name}] seed {seed}: train {last['train_psnr']:.2f} dB, test {last['test_psnr']:.2f} dB, gap {last['gap_db']:.2f} dB, "
                  f"test depth err {last['test_depth_err_m']:.3f} m ({last['seconds']:.0f} s)", flush=True)
    df = pd.DataFrame(rows)
    df.to_csv(out / "properties.csv", index=False)
    final = df[df.fraction == df.fraction.max()]
    summary = final.groupby("scene").agg(views=("seed", "size"), unseen_frac=("unseen_frac", "first"), disparity_px=("disparity_px", "first"),
                                         train_psnr=("train_psnr", "mean"), test_psnr=("test_psnr", "mean"),
                                         gap_db=("gap_db", "mean"), gap_std=("gap_db", "std"), test_depth_err_m=("test_depth_err_m", "mean"))
    summary = summary.rename(columns={"views": "seeds"})
    source = f"stored rows of {args.rows}" if args.rows else f"seeds {args.seeds}, overrides {args.set}"
    text = (f"# Few-shot scene properties ({args.method}, scale {args.scale}, {source})\n\n"
            + summary.to_markdown(floatfmt=".3f") + "\n")
    (out / "properties.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
