"""Print a MonoSDF training trajectory at fixed steps, to compare two code versions (or two configs) step by
step: how fast does a float-level difference grow into a different trajectory?

Usage (one line per compared version; run each from its own ``git worktree`` with PYTHONPATH pointing at it
and its own TORCH_EXTENSIONS_DIR, so each builds its own C++ kernel):

    .venv/bin/python scripts/trajectory_divergence.py [--scene scannet_like_0] [--scale small] [--seed 0]
        [--steps 300] [--set KEY=VALUE ...] [--threads 1]

Prints, at steps 0, 1, 5, 20, 50, 100, 200 and the last: the total loss, the colour and depth terms and the
L1 norm of the grid table. Identical code gives identical lines (the runs are deterministic); code that
differs only in the order of float operations agrees to ~7 digits for the first steps and then diverges
(docs/studies/float-rounding-chaos.md).
"""

from __future__ import annotations

import argparse

import torch


def main() -> None:
    from bench.data.datasets import load_dataset
    from bench.overrides import parse_overrides
    from methods.monosdf.trainer import MonoSDFTrainer
    from methods.registry import typed_method_config

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", default="scannet_like_0")
    ap.add_argument("--scale", default="small")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--steps", type=int, default=300)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--set", nargs="+", default=[], metavar="KEY=VALUE")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    scene = load_dataset(args.scene, args.scale)
    cfg = typed_method_config("monosdf", args.scale, {"iterations": 8000, **parse_overrides(args.set)})
    trainer = MonoSDFTrainer(scene, cfg, seed=args.seed)
    marks = {0, 1, 5, 20, 50, 100, 200, args.steps - 1}
    print("step loss colour depth |table|_1")
    for i in range(args.steps):
        logs = trainer.step()
        if i in marks:
            table = float(trainer.sdf.grid.table.detach().abs().sum())
            print(f"{i} {logs['loss']:.9g} {logs['color']:.9g} {logs.get('depth', float('nan')):.9g} {table:.9g}")


if __name__ == "__main__":
    main()
