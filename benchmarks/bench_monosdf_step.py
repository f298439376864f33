"""Benchmark: MonoSDF training-step throughput (forward + backward incl. the eikonal term) on 2 cores.

Prints ray-samples per second (rays_per_batch x (n_coarse + n_fine) samples rendered with gradients
per step; the coarse no-gradient pass and the eikonal points are included in the time, not the count)
and a per-op breakdown from torch.profiler.

Usage:
    .venv/bin/python benchmarks/bench_monosdf_step.py [--scene scannet_like_0] [--scale small] [--steps 20]
        [--rays 512] [--reference-grid] [--threads 2] [--no-profile] [--set prune_weight=1e-4]
        [--train 2000 --checkpoint /tmp/monosdf_2000.pt] [--cpu-time]

``--train N`` times the step at a late point of a schedule (beta small, most samples weightless: where
``prune_weight`` pays): N steps are trained first (with the config's other keys) and cached in
``--checkpoint``. ``--cpu-time`` reports the process's CPU time per step instead of wall time: on a
shared machine wall time includes time the process waited for a core.

Goal (issue 4): >= 0.5 M ray-samples/s.
"""

from __future__ import annotations

import argparse
import statistics
import time

import torch

from bench.data.datasets import load_dataset
from methods.monosdf.trainer import MonoSDFTrainer
from methods.registry import typed_method_config


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", default="scannet_like_0")
    ap.add_argument("--scale", default="small")
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--warmup", type=int, default=5)
    ap.add_argument("--rays", type=int, default=None)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--reference-grid", action="store_true", help="pure-PyTorch grid instead of the C++ kernel")
    ap.add_argument("--no-profile", action="store_true")
    ap.add_argument("--set", nargs="+", default=[], metavar="KEY=VALUE", help="config overrides (YAML values), e.g. pe_frequencies=0")
    ap.add_argument("--train", type=int, default=0, help="train this many steps first (a late point of the schedule)")
    ap.add_argument("--checkpoint", default=None, help="cache of the --train state (loaded if it exists)")
    ap.add_argument("--cpu-time", action="store_true", help="process CPU time per step instead of wall time")
    args = ap.parse_args()

    torch.set_num_threads(args.threads)
    scene = load_dataset(args.scene, args.scale)
    overrides = {"fast_grid": not args.reference_grid}
    if args.rays:
        overrides["rays_per_batch"] = args.rays
    from bench.study import parse_overrides

    overrides.update(parse_overrides(args.set))
    cfg = typed_method_config("monosdf", args.scale, overrides)
    trainer = MonoSDFTrainer(scene, cfg, seed=0)
    samples = cfg.rays_per_batch * (cfg.n_coarse + cfg.n_fine)
    if args.train:
        from pathlib import Path

        if args.checkpoint and Path(args.checkpoint).exists():
            trainer.load(args.checkpoint)
        else:
            for _ in range(args.train):
                trainer.step()
            if args.checkpoint:
                trainer.save(args.checkpoint)
        print(f"state after {trainer.step_count} steps: beta {float(trainer.density.beta()):.4f}")
    for _ in range(args.warmup):
        trainer.step()
    clock = time.process_time if args.cpu_time else time.perf_counter
    times = []
    sum0, count0 = trainer._log_sums.get("samples_rendered", 0.0), trainer._log_count
    for _ in range(args.steps):
        t = clock()
        trainer.step()
        times.append(clock() - t)
    rendered = (trainer._log_sums["samples_rendered"] - sum0) / (trainer._log_count - count0)
    print(f"samples rendered with gradients per ray (timed steps): {rendered:.1f} of {cfg.n_coarse + cfg.n_fine}"
          f" ({'cpu' if args.cpu_time else 'wall'} time below)")
    med, best = statistics.median(times), min(times)
    print(f"grid: {'reference (PyTorch)' if args.reference_grid else 'C++ kernel'}, threads {args.threads}, "
          f"{cfg.rays_per_batch} rays x {cfg.n_coarse + cfg.n_fine} samples = {samples} samples/step")
    print(f"step time: median {med * 1000:.1f} ms, best {best * 1000:.1f} ms")
    print(f"throughput: median {samples / med / 1e6:.3f} M samples/s, best {samples / best / 1e6:.3f} M samples/s")
    if not args.no_profile:
        from torch.profiler import ProfilerActivity, profile

        with profile(activities=[ProfilerActivity.CPU]) as prof:
            for _ in range(5):
                trainer.step()
        print(prof.key_averages().table(sort_by="self_cpu_time_total", row_limit=18))


if __name__ == "__main__":
    main()
