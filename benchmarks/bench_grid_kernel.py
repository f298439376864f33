"""Benchmark: the C++ feature-grid kernels alone (forward with the Jacobian, and its backward), on points laid
out like a training step's (``--rays`` rays from one camera, ``--samples`` sorted samples each, ray-major),
and on the same points shuffled (no spatial coherence): the AVX-512 kernels (the default where compiled), the
per-point kernels (their twin) and, with ``--reference``, the PyTorch reference path.

Usage:
    .venv/bin/python benchmarks/bench_grid_kernel.py [--threads 1] [--rays 512] [--samples 67] [--repeat 20]

The grid's layout is the MonoSDF default config's (8 levels x 2, 2^16 table, resolutions 16-256). Run it on
an idle machine: the kernel is memory-bound and its figures swing 2x when other processes share the caches.
"""

from __future__ import annotations

import argparse
import contextlib
import time

import torch

from bench.microbench import median_seconds
from methods.monosdf.grid import FeatureGrid, interpolate_fast, interpolate_reference, make_grid_spec, per_point_grid_kernel, simd_kernel_compiled


def ray_points(rays: int, samples: int, seed: int = 0) -> torch.Tensor:
    """(rays * samples, 3) points in [-1, 1]^3: rays from one camera at (0.1, -0.2, 0.05) in random directions,
    samples sorted along each ray in [0.02, 1.6], clamped to the cube (ray-major, as the renderer passes them)."""
    g = torch.Generator().manual_seed(seed)
    dirs = torch.nn.functional.normalize(torch.randn(rays, 3, generator=g), dim=-1)
    t, _ = torch.sort(0.02 + 1.58 * torch.rand(rays, samples, generator=g), dim=-1)
    pts = torch.tensor([0.1, -0.2, 0.05]) + dirs[:, None, :] * t[..., None]
    return pts.reshape(-1, 3).clamp(-1, 1).contiguous()


def timed(fn, repeat: int) -> float:
    """Median process CPU seconds of ``fn()`` over ``repeat`` calls (3 warm-up calls first)."""
    return median_seconds(fn, repeat, warmup=3, clock=time.process_time)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--rays", type=int, default=512)
    ap.add_argument("--samples", type=int, default=67)
    ap.add_argument("--repeat", type=int, default=20)
    ap.add_argument("--reference", action="store_true", help="also time the PyTorch reference path")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    spec = make_grid_spec(8, 2, 16, 16, 256)
    grid = FeatureGrid(spec, init_scale=0.1)
    coherent = ray_points(args.rays, args.samples)
    shuffled = coherent[torch.randperm(coherent.shape[0], generator=torch.Generator().manual_seed(1))].contiguous()
    paths = ([("AVX-512", interpolate_fast)] if simd_kernel_compiled() else []) + [("per-point", interpolate_fast)] \
        + ([("PyTorch", interpolate_reference)] if args.reference else [])
    print(f"{coherent.shape[0]} points, {args.threads} thread(s), process CPU time (median of {args.repeat})")
    for layout, x in (("ray-major", coherent), ("shuffled", shuffled)):
        for name, fn in paths:
            def fwd() -> None:
                with torch.no_grad():
                    fn(grid.table, x, spec, True)

            def fwd_bwd() -> None:
                feat, jac = fn(grid.table, x, spec, True)
                grid.table.grad = None
                (feat.sum() + jac.sum()).backward()

            with per_point_grid_kernel() if name == "per-point" else contextlib.nullcontext():
                f, fb = timed(fwd, args.repeat), timed(fwd_bwd, args.repeat)
            print(f"{layout:9s} {name:9s}: forward + Jacobian {1000 * f:6.2f} ms, with backward {1000 * fb:6.2f} ms "
                  f"({x.shape[0] / fb / 1e6:.2f} M points/s)")


if __name__ == "__main__":
    main()
