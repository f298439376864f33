"""Benchmark: a MonoSDF training step with ``torch.compile`` of the SDF and colour networks' forward vs eager.

The C++ kernels (grid, softplus and slope, positional encoding, Jacobian contraction) are opaque to TorchDynamo,
so each is a graph break: Inductor compiles the PyTorch ops between them (12 graphs, 16 breaks on the default
config). Each mode runs in its own process (compiled code is per process), alternating, ``--pairs`` times; a
process prints the wall time of its first 8 steps (compilation included; Inductor's on-disk cache in
``--cache-dir`` makes later processes compile faster) and the median / best process CPU time of ``--steps``
steps after them, 1 thread, scannet_like_0 small, step 0 of a fresh trainer.

Session 28 (AMD EPYC Zen 3, idle, 8 pairs over three invocations): no gain (compiled medians 86-142 ms, eager
86-100 ms; best 81-118 vs 76-88 ms); compilation 95 s with a cold cache, 6-9 s per process with a warm one. Not
used by the harness (docs/monosdf.md, speed).

Usage:
    .venv/bin/python benchmarks/bench_torch_compile.py [--pairs 3] [--steps 40] [--cache-dir /tmp/inductor_cache]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time


def run_one(compiled: bool, steps: int) -> None:
    """Time one trainer in this process and print its line."""
    import torch

    from bench.data.datasets import load_dataset
    from methods.monosdf.trainer import MonoSDFTrainer
    from methods.registry import typed_method_config

    torch.set_num_threads(1)
    trainer = MonoSDFTrainer(load_dataset("scannet_like_0", "small"), typed_method_config("monosdf", "small", {}), seed=0)
    if compiled:
        trainer.sdf.forward = torch.compile(trainer.sdf.forward, dynamic=True)  # type: ignore[method-assign]
        trainer.color.forward = torch.compile(trainer.color.forward, dynamic=True)  # type: ignore[method-assign]
    t = time.perf_counter()
    for _ in range(8):
        trainer.step()
    first = time.perf_counter() - t
    times = []
    for _ in range(steps):
        t = time.process_time()
        trainer.step()
        times.append(time.process_time() - t)
    name = "compiled" if compiled else "eager"
    print(f"{name:8s}: first 8 steps {first:6.1f} s wall; then cpu median {statistics.median(times) * 1e3:6.1f} ms, "
          f"best {min(times) * 1e3:6.1f} ms")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--pairs", type=int, default=3)
    ap.add_argument("--steps", type=int, default=40)
    ap.add_argument("--cache-dir", default="/tmp/inductor_cache", help="Inductor's cache (TORCHINDUCTOR_CACHE_DIR)")
    ap.add_argument("--one", choices=["compiled", "eager"], default=None, help=argparse.SUPPRESS)  # a child process
    args = ap.parse_args()
    if args.one:
        from bench.mkl_dispatch import reexec_with_mkl_shim

        reexec_with_mkl_shim()  # the matrix-product path `bench` runs with
        run_one(args.one == "compiled", args.steps)
        return
    env = {**os.environ, "TORCHINDUCTOR_CACHE_DIR": args.cache_dir}
    for _ in range(args.pairs):
        for one in ("compiled", "eager"):
            done = subprocess.run([sys.executable, __file__, "--one", one, "--steps", str(args.steps)], env=env,
                                  capture_output=True, text=True)
            if done.returncode != 0:
                raise SystemExit(f"{one} run failed:\n{done.stderr[-2000:]}")
            print(done.stdout.strip().splitlines()[-1])


if __name__ == "__main__":
    main()
