"""Benchmark: float32 matrix products of the MLP shapes on MKL's generic path vs its AVX-512 or AVX2 path (bench/mkl_dispatch.py).

Runs itself twice in fresh processes, with ``BENCH_MKL_AVX512=0`` (MKL's own choice: the generic path on a
non-Intel CPU) and ``=1`` (the shim preloaded where :func:`bench.mkl_dispatch.wants_shim` says so), and prints
ms and GFLOP/s per product: forward ``X @ W``, the weight gradient ``X^T @ G`` and the input gradient
``G @ W^T`` of a linear layer of P points, for the layer shapes of MonoSDF's networks (55 = 16 grid features
+ 39 positional encoding into 32; 32 -> 32; 32 -> 16; the colour network's 24 -> 32), and a 1024^3 product.

Usage:
    .venv/bin/python benchmarks/bench_mkl_dispatch.py [--points 32768] [--threads 1] [--repeats 30]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys

from bench.microbench import median_seconds

SHAPES = [(55, 32), (32, 32), (32, 16), (24, 32)]


def _median_ms(fn, repeats: int) -> float:
    return 1e3 * median_seconds(fn, repeats)


def measure(points: int, threads: int, repeats: int) -> None:
    """Time the products in this process and print one line per shape."""
    import torch

    from bench.mkl_dispatch import blas_path, mkl_code_path, reexec_with_mkl_shim

    reexec_with_mkl_shim()
    torch.set_num_threads(threads)
    torch.manual_seed(0)
    print(f"MKL {mkl_code_path()} path (blas: {blas_path()}), {threads} thread(s), P = {points}")
    for k, n in SHAPES:
        x, w, g = torch.randn(points, k), torch.randn(k, n), torch.randn(points, n)
        gflop = 2.0 * points * k * n / 1e9
        cells = []
        for label, fn in (("X@W", lambda: x @ w), ("X^T@G", lambda: x.t() @ g), ("G@W^T", lambda: g @ w.t())):
            ms = _median_ms(fn, repeats)
            cells.append(f"{label} {ms:6.3f} ms {gflop / ms * 1e3:5.0f} GF/s")
        print(f"  ({points} x {k}) @ ({k} x {n}):  " + "   ".join(cells))
    a, b = torch.randn(1024, 1024), torch.randn(1024, 1024)
    ms = _median_ms(lambda: a @ b, max(5, repeats // 3))
    print(f"  1024^3: {ms:6.2f} ms {2 * 1024**3 / 1e9 / ms * 1e3:5.0f} GF/s")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--points", type=int, default=32768)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--repeats", type=int, default=30)
    ap.add_argument("--inner", action="store_true", help=argparse.SUPPRESS)  # one measurement in this process
    args = ap.parse_args()
    if args.inner:
        measure(args.points, args.threads, args.repeats)
        return
    for switch in ("0", "1"):
        env = {**os.environ, "BENCH_MKL_AVX512": switch}
        env.pop("BENCH_MKL_SHIM_TRIED", None)
        subprocess.run([sys.executable, __file__, "--inner", "--points", str(args.points), "--threads", str(args.threads),
                        "--repeats", str(args.repeats)], env=env, check=True)


if __name__ == "__main__":
    main()
