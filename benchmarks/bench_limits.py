"""Benchmark: how far the MonoSDF training step is from what this machine's cores deliver.

Prints, for one config:
  * the machine's measured float32 matmul peak (a 2048^3 product, and a (32768 x 32) @ (32 x 32) product:
    the shape of our MLP layers) at 1 and ``--threads`` threads;
  * the step's throughput (ray-samples per second; samples = rays x (n_coarse + n_fine) rendered with
    gradients) and the FLOPs of one step, counted: every matmul / elementwise-free aten op torch's
    ``FlopCounterMode`` knows (the MLPs, forward and backward), plus the grid kernel's trilinear
    multiply-adds counted analytically (:func:`grid_flops`; the C++ kernel is invisible to torch);
  * FLOPs per rendered sample and the fraction of the measured peak the step reaches;
  * effective samples per ray: how many of the rendered samples carry weight > 1e-4 at this point of
    training (``--train N`` steps first; the study's ``samples_weighted`` column gives it along a schedule).

Usage:
    .venv/bin/python benchmarks/bench_limits.py [--scene scannet_like_0] [--scale small] [--threads 2]
        [--steps 20] [--train 0] [--set KEY=VALUE ...]

Run it on an idle machine: the figures are medians of ``--steps`` steps and vary +-10 % on this VM.
"""

from __future__ import annotations

import argparse
import statistics
import time

import torch


def matmul_gflops(m: int, k: int, n: int, threads: int, repeats: int = 10) -> float:
    """Median GFLOP/s of a float32 (m x k) @ (k x n) product at ``threads`` torch threads."""
    torch.set_num_threads(threads)
    a, b = torch.randn(m, k), torch.randn(k, n)
    for _ in range(3):
        a @ b
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        a @ b
        times.append(time.perf_counter() - t)
    return 2.0 * m * k * n / statistics.median(times) / 1e9


def grid_flops(points: int, levels: int, features: int, with_jacobian: bool) -> float:
    """Multiply-adds (x2 = FLOPs) of the grid kernel for ``points`` lookups, forward + backward.

    Per level and point: 8 corner weights (3 products each of the lerp factors: 24 FLOPs incl. the
    1 - t terms), the feature blend (8 x F multiply-adds), with the Jacobian 3 x 8 x F more (derivative
    weights cost another 3 x 24); the backward scatters the same products into the table gradient
    (8 x F, and 3 x 8 x F for the Jacobian's gradient)."""
    per = 24 + 2 * 8 * features
    if with_jacobian:
        per += 3 * 24 + 2 * 3 * 8 * features
    backward = 2 * 8 * features + (2 * 3 * 8 * features if with_jacobian else 0)
    return float(points * levels * (per + backward))


def main() -> None:
    from bench.machine import cpu_description
    from bench.mkl_dispatch import mkl_code_path, reexec_with_mkl_shim

    reexec_with_mkl_shim()  # MKL's Intel (AVX-512 / AVX2) path on a non-Intel CPU, as `bench` runs (BENCH_MKL_AVX512=0: the generic path)
    print(f"matrix products: MKL {mkl_code_path()} path; CPU: {cpu_description()}")
    from torch.utils.flop_counter import FlopCounterMode

    from bench.data.datasets import load_dataset
    from bench.overrides import parse_overrides
    from methods.monosdf.trainer import WEIGHTED_SAMPLE, MonoSDFTrainer
    from methods.registry import typed_method_config

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", default="scannet_like_0")
    ap.add_argument("--scale", default="small")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--train", type=int, default=0, help="train this many steps before measuring (effective samples change)")
    ap.add_argument("--set", nargs="+", default=[], metavar="KEY=VALUE")
    args = ap.parse_args()

    cfg = typed_method_config("monosdf", args.scale, parse_overrides(args.set))
    if cfg.sampler != "hierarchical":  # refuse before any measurement
        raise SystemExit(f"bench_limits counts the FLOPs of the hierarchical sampler only (sampler: {cfg.sampler})")
    peaks = {}
    for threads in sorted({1, args.threads}):
        peaks[threads] = (matmul_gflops(2048, 2048, 2048, threads, 5), matmul_gflops(32768, 32, 32, threads))
        print(f"matmul peak, {threads} thread(s): 2048^3 {peaks[threads][0]:.0f} GFLOP/s, "
              f"(32768 x 32) @ (32 x 32) {peaks[threads][1]:.0f} GFLOP/s")

    torch.set_num_threads(args.threads)
    scene = load_dataset(args.scene, args.scale)
    trainer = MonoSDFTrainer(scene, cfg, seed=0)
    for _ in range(max(args.train, 3)):
        trainer.step()
    samples = cfg.rays_per_batch * cfg.samples_per_ray()

    times = []
    for _ in range(args.steps):
        t = time.perf_counter()
        trainer.step()
        times.append(time.perf_counter() - t)
    step_s = statistics.median(times)

    counter = FlopCounterMode(display=False)
    with counter:
        trainer.step()
    torch_flops = float(counter.get_total_flops())
    R = cfg.rays_per_batch
    n_extra = R * (3 if cfg.smooth_weight > 0 else 1)  # eikonal / smoothness points in the SDF pass
    levels, feats = cfg.grid_levels, cfg.grid_features
    # coarse pass: features only, no backward; rendering pass: features + Jacobian, forward and backward
    coarse = grid_flops(R * cfg.n_coarse, levels, feats, False) - R * cfg.n_coarse * levels * 2 * 8 * feats
    render = grid_flops(samples + n_extra, levels, feats, True)
    total = torch_flops + coarse + render
    weighted = trainer.diagnostics().get("samples_weighted", float("nan"))

    gflops = total / step_s / 1e9
    print(f"config: {R} rays x {cfg.n_coarse} + {cfg.n_fine} samples, grid {levels} x {feats}, MLP {cfg.mlp_hidden} wide, "
          f"{args.threads} thread(s), after {max(args.train, 3) + args.steps} steps")
    print(f"step: median {step_s * 1000:.1f} ms -> {samples / step_s / 1e6:.3f} M ray-samples/s")
    print(f"FLOPs per step: {total / 1e9:.2f} G (torch-counted ops {torch_flops / 1e9:.2f} G, grid kernel {(coarse + render) / 1e9:.2f} G) "
          f"= {total / samples / 1e3:.1f} kFLOP per rendered sample")
    print(f"achieved {gflops:.1f} GFLOP/s = {100 * gflops / peaks[args.threads][0]:.1f} % of the 2048^3 peak, "
          f"{100 * gflops / peaks[args.threads][1]:.1f} % of the MLP-shaped peak ({args.threads} threads)")
    print(f"compute-bound limit at this FLOP count: {peaks[args.threads][1] * 1e9 / (total / samples) / 1e6:.1f} M ray-samples/s (MLP-shaped peak)")
    print(f"effective samples per ray (weight > {WEIGHTED_SAMPLE:g}): {weighted:.1f} of {cfg.samples_per_ray()} "
          f"(in the steps measured)")


if __name__ == "__main__":
    main()
