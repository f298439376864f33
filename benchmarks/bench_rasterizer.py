"""Throughput of the CPU Gaussian rasteriser (forward + backward), in Gaussian-pixel pairs per second.

Random Gaussians inside the frustum of a 128 x 96 camera (the ``small`` LLFF-like resolution; K like
the llff_like scenes: f = 110.9 px) at z in [1.5, 6] m, scales log-uniform in [0.005, 0.05] m
(1-10 px footprints, like a trained few-shot scene), opacities uniform in [0.1, 0.9], SH-free colours.
Loss = sum of colour + depth + alpha, so every output is back-propagated.

Figures reported per N: milliseconds for forward, backward and both (median of ``--repeat`` runs after one
warm-up), candidate pairs (inside 3-sigma boxes), contributing pairs (alpha >= 1/255, up to the
transmittance cut-off) and pairs/s = contributing pairs / (forward + backward) seconds, for each ``--kernel``:
``cpp`` (the default path: projection and per-pixel compositing in C++, ``methods/gaussians/raster_kernel.py``) and
``torch`` (its PyTorch twin).

    python benchmarks/bench_rasterizer.py [--sizes 1000 10000 50000] [--width 128 --height 96] [--repeat 5] [--threads 1]
        [--kernel cpp torch]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from methods.gaussians.rasterize import rasterize_gaussians  # noqa: E402


def make_gaussians(n: int, width: int, height: int, focal: float, seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    z = 1.5 + 4.5 * torch.rand(n, generator=g)
    u = torch.rand(n, generator=g) * width
    v = torch.rand(n, generator=g) * height
    means = torch.stack([(u - (width - 1) / 2) * z / focal, (v - (height - 1) / 2) * z / focal, z], -1)
    scales = torch.exp(torch.empty(n, 3).uniform_(torch.log(torch.tensor(0.005)).item(), torch.log(torch.tensor(0.05)).item(), generator=g))
    quats = torch.randn(n, 4, generator=g)
    opac = 0.1 + 0.8 * torch.rand(n, generator=g)
    colors = torch.rand(n, 3, generator=g)
    return [t.requires_grad_() for t in (means, quats, scales, opac, colors)]


def run(n: int, width: int, height: int, repeat: int, kernel: str) -> dict:
    focal = 110.85 * width / 128
    K = torch.tensor([[focal, 0, (width - 1) / 2], [0, focal, (height - 1) / 2], [0, 0, 1.0]])
    vm = torch.eye(4)
    params = make_gaussians(n, width, height, focal)
    fw, bw, info = [], [], {}
    for it in range(repeat + 1):
        for p in params:
            p.grad = None
        t0 = time.perf_counter()
        out = rasterize_gaussians(*params, vm, K, width, height, background=torch.ones(3), kernel=kernel)
        t1 = time.perf_counter()
        (out["color"].sum() + out["depth"].sum() + out["alpha"].sum()).backward()
        t2 = time.perf_counter()
        if it:  # first run = warm-up
            fw.append(t1 - t0)
            bw.append(t2 - t1)
        info = {"pairs": out["n_pairs"], "candidates": out["n_candidates"]}
    f, b = statistics.median(fw), statistics.median(bw)
    return {"n": n, "fwd_ms": 1e3 * f, "bwd_ms": 1e3 * b, "total_ms": 1e3 * (f + b), **info, "pairs_per_s": info["pairs"] / (f + b)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[1000, 10000, 50000])
    ap.add_argument("--width", type=int, default=128)
    ap.add_argument("--height", type=int, default=96)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--threads", type=int, default=1, help="torch threads (the Gaussian configs use 1; the C++ kernels are serial)")
    ap.add_argument("--kernel", nargs="+", default=["cpp", "torch"], choices=["cpp", "torch"])
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    print(f"torch {torch.__version__}, {args.threads} threads, image {args.width} x {args.height}")
    print(f"{'kernel':>6} {'N':>7} {'fwd ms':>8} {'bwd ms':>8} {'total ms':>9} {'candidates':>11} {'pairs':>9} {'M pairs/s':>10}")
    for n in args.sizes:
        for kernel in args.kernel:
            r = run(n, args.width, args.height, args.repeat, kernel)
            print(f"{kernel:>6} {r['n']:>7} {r['fwd_ms']:>8.1f} {r['bwd_ms']:>8.1f} {r['total_ms']:>9.1f} {r['candidates']:>11} {r['pairs']:>9} {r['pairs_per_s'] / 1e6:>10.2f}")


if __name__ == "__main__":
    main()
