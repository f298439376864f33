"""Benchmark: MonoSDF training-step throughput (forward + backward incl. the eikonal term) on 2 cores.

Prints ray-samples per second (rays_per_batch x (n_coarse + n_fine) samples rendered with gradients
per step; the coarse no-gradient pass and the eikonal points are included in the time, not the count)
and a per-op breakdown from torch.profiler.

Usage:
    .venv/bin/python benchmarks/bench_monosdf_step.py [--scene scannet_like_0] [--scale small] [--steps 20]
        [--rays 512] [--reference-grid | --per-point-grid] [--threads 2] [--no-profile] [--set prune_weight=1e-4]
        [--train 2000 --checkpoint /tmp/monosdf_2000.pt] [--cpu-time] [--phases] [--processes 2] [--compile]

``--train N`` times the step at a late point of a schedule (beta small, most samples weightless: where
``prune_weight`` pays): N steps are trained first (with the config's other keys) and cached in
``--checkpoint``. ``--cpu-time`` reports the process's CPU time per step instead of wall time: on a
shared machine wall time includes time the process waited for a core. ``--processes N`` runs N copies of the
benchmark side by side, each with one thread and no profile (how ``bench run`` uses 2 cores: two single-threaded
jobs), and prints their summed throughput (the copies share memory bandwidth and caches, so this is below N times
the throughput of one copy alone). ``--compile`` wraps the SDF and colour networks' forward in ``torch.compile``
(``dynamic=True``; the C++ kernels are graph breaks) and prints the warmup's wall time, compilation included
(Inductor's on-disk cache, ``TORCHINDUCTOR_CACHE_DIR``, shortens it in later processes); the harness does not use it
(no gain: docs/studies/monosdf-speed.md).

Goals: >= 0.5 M ray-samples/s for one job (met), >= 2 M on 2 cores (not yet met: 1.36 M for one job
on 2 threads on an AMD EPYC, 1.66 M for two single-threaded copies side by side, ``--processes 2``).
"""

from __future__ import annotations

import argparse
import contextlib
import statistics
import time
from typing import Callable, Iterator

import torch

from bench.data.datasets import load_dataset
from methods.monosdf.trainer import MonoSDFTrainer
from methods.registry import typed_method_config

PHASES = ("step.sampler", "sampler.sdf", "sampler.sdf_with_gradient", "step.render", "render.prune_pass", "render.sdf_with_gradient",
          "render.color", "step.backward", "step.optimizer")  # the record_function labels of MonoSDFTrainer.step / render_rays / the samplers (sampler.sdf: inside step.sampler)


class PhaseClock:
    """Stands in for ``torch.profiler.record_function`` in the trainer and renderer modules: each labelled
    range adds its wall time (``clock``) to ``seconds[label]``, without the profiler's per-op recording
    (which inflated a profiled step by up to 1.8x (1.05-1.8x over three runs), most the backward's many small ops)."""

    def __init__(self, clock: Callable[[], float]) -> None:
        self.clock = clock
        self.seconds: dict[str, float] = {}

    @contextlib.contextmanager
    def __call__(self, label: str) -> Iterator[None]:
        t = self.clock()
        try:
            yield
        finally:
            self.seconds[label] = self.seconds.get(label, 0.0) + self.clock() - t


def time_phases(trainer: MonoSDFTrainer, steps: int, clock: Callable[[], float]) -> None:
    """Run ``steps`` more steps with :class:`PhaseClock` in place of the modules' ``record_function`` and
    print ms per step and % of the step per phase (inclusive; ``render.*`` lie inside ``step.render``; the
    rest of a step is the loss terms and bookkeeping)."""
    import methods.monosdf.error_bounded as error_bounded_mod
    import methods.monosdf.render as render_mod
    import methods.monosdf.trainer as trainer_mod

    phase = PhaseClock(clock)
    modules = (error_bounded_mod, render_mod, trainer_mod)
    saved = [m.record_function for m in modules]
    for m in modules:
        setattr(m, "record_function", phase)
    try:
        t = clock()
        for _ in range(steps):
            trainer.step()
        total = (clock() - t) / steps
    finally:
        for m, original in zip(modules, saved):
            setattr(m, "record_function", original)
    print(f"phases over {steps} steps ({total * 1000:.1f} ms per step; inclusive, render.* inside step.render, sampler.* inside step.sampler):")
    for name in PHASES:
        if name in phase.seconds:
            ms = phase.seconds[name] * 1000.0 / steps
            print(f"  {name:28s} {ms:7.1f} ms  {100.0 * ms / (total * 1000.0):5.1f} %")


def run_side_by_side(n: int) -> None:
    """Start ``n`` copies of this benchmark (same arguments, ``--threads 1 --no-profile``, no ``--phases``) at
    once, wait for all, and print each copy's throughput line and their sum."""
    import re
    import subprocess
    import sys

    argv = [a for a in sys.argv[1:] if a != "--phases"]
    # the appended options override the caller's in any spelling (argparse keeps the last occurrence), so a
    # copy never starts copies of its own ("--processes=2" and "--proc 2" were not caught by a flag filter)
    cmd = [sys.executable, __file__, *argv, "--threads", "1", "--processes", "1", "--no-profile"]
    procs = [subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True) for _ in range(n)]
    total = 0.0
    for k, proc in enumerate(procs):
        out, _ = proc.communicate()
        if proc.returncode != 0:
            raise SystemExit(f"copy {k} failed (exit {proc.returncode}):\n{out}")
        line = next(ln for ln in out.splitlines() if ln.startswith("throughput:"))
        step = next(ln for ln in out.splitlines() if ln.startswith("step time:"))
        print(f"copy {k}: {step}; {line}")
        total += float(re.search(r"median ([0-9.]+) M", line).group(1))  # type: ignore[union-attr]
    print(f"{n} single-threaded copies side by side: {total:.3f} M samples/s in total (sum of the medians)")


def main() -> None:
    from bench.machine import cpu_description
    from bench.mkl_dispatch import mkl_code_path, reexec_with_mkl_shim

    reexec_with_mkl_shim()  # MKL's Intel (AVX-512 / AVX2) path on a non-Intel CPU, as `bench` runs (BENCH_MKL_AVX512=0: the generic path)
    print(f"matrix products: MKL {mkl_code_path()} path; CPU: {cpu_description()}")
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", default="scannet_like_0")
    ap.add_argument("--scale", default="small")
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--warmup", type=int, default=5)
    ap.add_argument("--rays", type=int, default=None)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--reference-grid", action="store_true", help="pure-PyTorch grid instead of the C++ kernel")
    ap.add_argument("--per-point-grid", action="store_true", help="the C++ kernel's per-point grid kernels instead of its AVX-512 ones")
    ap.add_argument("--no-profile", action="store_true")
    ap.add_argument("--set", nargs="+", default=[], metavar="KEY=VALUE", help="config overrides (YAML values), e.g. pe_frequencies=0")
    ap.add_argument("--train", type=int, default=0, help="train this many steps first (a late point of the schedule)")
    ap.add_argument("--checkpoint", default=None, help="cache of the --train state (loaded if it exists)")
    ap.add_argument("--cpu-time", action="store_true", help="process CPU time per step instead of wall time")
    ap.add_argument("--phases", action="store_true", help="then time the step's phases (sampler, render, prune pass, "
                    "SDF with gradient, colour, backward, optimiser) over --steps more steps")
    ap.add_argument("--processes", type=int, default=1, help="run this many single-threaded copies side by side and "
                    "print their summed throughput (the tables' regime: one job per core)")
    ap.add_argument("--compile", action="store_true", help="torch.compile the SDF and colour networks' forward "
                    "(an experiment: not used by the harness); prints the warmup's wall time, compilation included")
    args = ap.parse_args()
    if args.processes > 1:
        run_side_by_side(args.processes)
        return

    torch.set_num_threads(args.threads)
    kernels = contextlib.ExitStack()  # held until main returns (a bare __enter__() would be undone when collected)
    if args.per_point_grid:
        from methods.monosdf.grid import per_point_grid_kernel

        kernels.enter_context(per_point_grid_kernel())
    scene = load_dataset(args.scene, args.scale)
    overrides = {"fast_grid": not args.reference_grid}
    if args.rays:
        overrides["rays_per_batch"] = args.rays
    from bench.overrides import parse_overrides

    overrides.update(parse_overrides(args.set))
    cfg = typed_method_config("monosdf", args.scale, overrides)
    trainer = MonoSDFTrainer(scene, cfg, seed=0)
    samples = cfg.rays_per_batch * cfg.samples_per_ray()
    if args.train:
        from pathlib import Path

        if args.checkpoint and Path(args.checkpoint).exists():
            trainer.load(args.checkpoint)
        else:
            for _ in range(args.train):
                trainer.step()
            if args.checkpoint:
                trainer.save(args.checkpoint)
        print(f"state after {trainer.step_count} steps: beta {float(trainer.density.beta().detach()):.4f}")
    if args.compile:
        trainer.sdf.forward = torch.compile(trainer.sdf.forward, dynamic=True)  # type: ignore[method-assign]
        trainer.color.forward = torch.compile(trainer.color.forward, dynamic=True)  # type: ignore[method-assign]
    t = time.perf_counter()
    for _ in range(args.warmup):
        trainer.step()
    if args.compile:
        print(f"torch.compile: {args.warmup} warmup steps took {time.perf_counter() - t:.1f} s wall, compilation included")
    clock = time.process_time if args.cpu_time else time.perf_counter
    times = []
    sum0, count0 = trainer._log_sums.get("samples_rendered", 0.0), trainer._log_count
    for _ in range(args.steps):
        t = clock()
        trainer.step()
        times.append(clock() - t)
    rendered = (trainer._log_sums["samples_rendered"] - sum0) / (trainer._log_count - count0)
    print(f"samples rendered with gradients per ray (timed steps): {rendered:.1f} of {cfg.samples_per_ray()}"
          f" ({'cpu' if args.cpu_time else 'wall'} time below)")
    med, best = statistics.median(times), min(times)
    from methods.monosdf.grid import simd_kernel_compiled

    kernel = "reference (PyTorch)" if args.reference_grid else ("C++ per-point" if args.per_point_grid or not simd_kernel_compiled() else "C++ AVX-512")
    print(f"grid: {kernel}, threads {args.threads}, "
          f"{cfg.rays_per_batch} rays x {cfg.samples_per_ray()} samples = {samples} samples/step")
    print(f"step time: median {med * 1000:.1f} ms, best {best * 1000:.1f} ms")
    print(f"throughput: median {samples / med / 1e6:.3f} M samples/s, best {samples / best / 1e6:.3f} M samples/s")
    if args.phases:
        time_phases(trainer, args.steps, clock)
    if not args.no_profile:
        from torch.profiler import ProfilerActivity, profile

        with profile(activities=[ProfilerActivity.CPU]) as prof:
            for _ in range(5):
                trainer.step()
        print(prof.key_averages().table(sort_by="self_cpu_time_total", row_limit=18))


if __name__ == "__main__":
    main()
