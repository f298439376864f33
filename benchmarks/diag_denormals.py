"""Diagnostic: which matrix products of a MonoSDF training step meet float32 denormals (|x| < 1.18e-38).

Arithmetic on denormals takes a slow path on x86 (microcode assists), so a product with a few percent denormal
operands runs several times slower; ``flush_denormals`` (config, default on) flushes them to 0. This script runs one
step from a checkpoint with ``flush_denormals=false`` and prints, per call site of ``aten::mm`` / ``aten::addmm``
(shapes included), the share of operand elements that are denormal.

Usage (the checkpoint from the step benchmark, a late point of the schedule):
    .venv/bin/python benchmarks/bench_monosdf_step.py --train 2000 --checkpoint /tmp/monosdf_2000.pt --steps 1 --no-profile
    .venv/bin/python benchmarks/diag_denormals.py --checkpoint /tmp/monosdf_2000.pt [--scene scannet_like_0] [--scale small]

Measured on a 2000-iteration checkpoint of scannet_like_0 (small): 0.9-2.6 % of the operands of the SDF MLP's
backward products (the (34304, 32) gradients of the pre-activations and the weight-gradient products) were
denormal, none of the forward's; with them ``aten::mm`` took 609 ms over 5 profiled steps, 92 ms flushed.
"""

from __future__ import annotations

import argparse
import collections
import traceback
from typing import Any

import torch
from torch.utils._python_dispatch import TorchDispatchMode

from bench.data.datasets import load_dataset
from methods.monosdf.trainer import MonoSDFTrainer
from methods.registry import typed_method_config

TINY = torch.finfo(torch.float32).tiny  # smallest normal float32


def denormal_count(t: torch.Tensor) -> int:
    """Number of nonzero elements of ``t`` below the smallest normal float32 in magnitude."""
    return int(((t != 0) & (t.abs() < TINY)).sum())


class CountDenormalOperands(TorchDispatchMode):
    """Counts denormal operand elements of every mm / addmm, keyed by the innermost ``methods/`` frame and the shapes."""

    def __init__(self) -> None:
        super().__init__()
        self.stats: dict[str, list[int]] = collections.defaultdict(lambda: [0, 0, 0])  # calls, denormal, elements

    def __torch_dispatch__(self, func: Any, types: Any, args: tuple = (), kwargs: dict | None = None) -> Any:
        if func in (torch.ops.aten.mm.default, torch.ops.aten.addmm.default):
            ops = [a for a in args if isinstance(a, torch.Tensor)]
            frames = [f for f in traceback.extract_stack() if "/methods/" in f.filename]
            where = f"{frames[-1].filename.split('/methods/')[1]}:{frames[-1].lineno}" if frames else "?"
            s = self.stats[f"{func.__name__} {where} " + " x ".join(str(tuple(a.shape)) for a in ops)]
            s[0] += 1
            s[1] += sum(denormal_count(a) for a in ops)
            s[2] += sum(a.numel() for a in ops)
        return func(*args, **(kwargs or {}))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--checkpoint", required=True, help="a trainer checkpoint (bench_monosdf_step.py --train N --checkpoint PATH)")
    ap.add_argument("--scene", default="scannet_like_0")
    ap.add_argument("--scale", default="small")
    args = ap.parse_args()
    torch.set_num_threads(1)
    cfg = typed_method_config("monosdf", args.scale, {"flush_denormals": False})
    trainer = MonoSDFTrainer(load_dataset(args.scene, args.scale), cfg, seed=0)
    trainer.load(args.checkpoint)
    counter = CountDenormalOperands()
    with counter:
        trainer.step()
    print("denormal share  count  calls  site (trainer.py's backward() line: autograd's products)")
    for site, (calls, d, total) in sorted(counter.stats.items(), key=lambda kv: -kv[1][1]):
        print(f"{d / max(total, 1):8.2%}  {d:9d}  {calls:3d}  {site}")


if __name__ == "__main__":
    main()
