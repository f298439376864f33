"""Benchmark: time `bench scenes make` for each shipped preset and print seconds and dataset size.

Usage:
    .venv/bin/python benchmarks/bench_scenes_make.py [--scale small] [--repeat 3]

Goal: each small-scale preset <= 10 s on 2 cores.
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
import time
from pathlib import Path

from bench.data.synth.make import make_dataset

SCENES = Path(__file__).resolve().parent.parent / "configs" / "scenes"
PRESETS = ["scannet_like_0", "replica_like_0", "dtu_like_0", "llff_like_0"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scale", default="small")
    ap.add_argument("--repeat", type=int, default=3, help="runs per preset; the best is reported")
    args = ap.parse_args()
    print(f"{'preset':16s} {'format':8s} {'views':>5s} {'size':>9s} {'best s':>7s} {'MB':>7s}")
    for name in PRESETS:
        best, info = float("inf"), None
        for _ in range(args.repeat):
            out = Path(tempfile.mkdtemp()) / name
            t = time.perf_counter()
            info = make_dataset(SCENES / f"{name}.yaml", out, scale=args.scale)
            best = min(best, time.perf_counter() - t)
            shutil.rmtree(out.parent)
        assert info is not None
        print(f"{name:16s} {info['format']:8s} {info['views']:5d} {info['width']:4d}x{info['height']:<4d} {best:7.2f} {info['bytes'] / 1e6:7.1f}")


if __name__ == "__main__":
    main()
