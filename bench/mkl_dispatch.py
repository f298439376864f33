"""MKL's Intel code paths (AVX-512, AVX2) on non-Intel CPUs: a process-level switch for ``bench`` and the benchmarks.

The pinned torch CPU wheel does its float32 matrix products (``aten::mm`` / ``addmm``: every MLP layer of
MonoSDF and MonoInstance, forward and backward) with Intel oneMKL. MKL picks its code path by CPU *vendor*
(``mkl_serv_intel_cpu_true``), not by the instructions the CPU has: on an AMD CPU with AVX-512 it runs a
generic path. Measured on this project's 2-core AMD EPYC (Zen 5, AVX-512), 1 thread, float32
(``benchmarks/bench_mkl_dispatch.py``): the (32768 x 32) @ (32 x 32) product of our MLP layers 91 -> 233
GFLOP/s, 1024^3 111 -> 254 GFLOP/s; a whole MonoSDF training step 62-65 -> 51-55 ms (docs/performance.md). On an
AMD EPYC without AVX-512 (Zen 3, AVX2) MKL's AVX2 path instead of the generic one: the MLP
products 55-74 -> 67-94 GFLOP/s (1024^3 unchanged at ~90, the core's peak), a step -8 % (best of 40 steps
85-94 -> 79-85 ms, process CPU time, 1 thread, five alternating pairs).

The switch is the long-known interposition of that one function: a shared library defining
``int mkl_serv_intel_cpu_true(void) { return 1; }``, loaded first with ``LD_PRELOAD``. MKL then checks the
CPU's actual instruction set (CPUID feature bits) as it does on an Intel CPU, and takes the AVX-512 path
where the CPU reports AVX-512, else the AVX2 path where it reports AVX2 and FMA. The dynamic loader resolves
the symbol at process start, so the switch needs a new process: :func:`reexec_with_mkl_shim` re-executes the
``bench`` command once with the library preloaded (workers, the fork server and Dask's local workers inherit
the environment).

What changes is the order of float operations inside each matrix product, nothing else: the same inputs give
the same products to float32 rounding (``tests/harness/test_mkl_dispatch.py`` compares the two paths on
matrices and on whole MonoSDF steps). Long training runs are chaotic to rounding (docs/studies/float-rounding-chaos.md),
so the path is recorded in every job row (``blas``) and enters the full job id like the thread count
(:func:`bench.runner.job_id_for`): a row computed on the other path is never silently reused.

Off switch: ``BENCH_MKL_AVX512=0`` (the generic path, exactly as before this module; the name is older than
the AVX2 case, which it switches off too). Nothing happens on an Intel CPU (MKL takes its own paths there), on
a CPU with neither AVX-512 nor AVX2 + FMA, off Linux, or without a C compiler (a one-line note on stderr).
"""

from __future__ import annotations

import functools
import hashlib
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ENV_SWITCH = "BENCH_MKL_AVX512"      # "0": keep MKL's generic path (also on an AVX2-only CPU)
ENV_TRIED = "BENCH_MKL_SHIM_TRIED"   # set before the re-exec: never loop
SHIM_SOURCE = "int mkl_serv_intel_cpu_true(void) { return 1; }\n"
SHIM_STEM = "libbench_mkl_intel_path"

# mkl_serv_cpu_detect(): the code path MKL dispatches to (measured with MKL_ENABLE_INSTRUCTIONS under the shim)
MKL_CODE_PATHS = {0: "generic (non-Intel CPU)", 3: "SSE4.2", 5: "AVX2", 7: "AVX-512"}


def cpu_facts(cpuinfo: str) -> tuple[str, str]:
    """(vendor id, widest vector extension MKL has a path for: ``"avx512"`` (AVX-512F), ``"avx2"`` (AVX2 and
    FMA) or ``""``) from the text of ``/proc/cpuinfo`` (first processor block)."""
    vendor, simd = "", ""
    for line in cpuinfo.splitlines():
        key, _, value = line.partition(":")
        key = key.strip()
        if key == "vendor_id" and not vendor:
            vendor = value.strip()
        elif key == "flags":
            flags = set(value.split())
            simd = "avx512" if "avx512f" in flags else "avx2" if {"avx2", "fma"} <= flags else ""
            break
    return vendor, simd


def wants_shim(cpuinfo: str, env: dict[str, str] | os._Environ[str], platform: str = sys.platform) -> bool:
    """Whether this process should run with the shim: Linux, a non-Intel CPU with AVX-512F or AVX2 + FMA, not
    switched off."""
    if platform != "linux" or env.get(ENV_SWITCH, "1") == "0":
        return False
    vendor, simd = cpu_facts(cpuinfo)
    return bool(vendor) and vendor != "GenuineIntel" and bool(simd)


def _read_cpuinfo() -> str:
    try:
        return Path("/proc/cpuinfo").read_text()
    except OSError:
        return ""


def cache_dir() -> Path:
    """Where the compiled shim is kept: ``$BENCH_BUILD_CACHE`` or ``$XDG_CACHE_HOME/monoinstance_bench``
    (default ``~/.cache/monoinstance_bench``)."""
    if os.environ.get("BENCH_BUILD_CACHE"):
        return Path(os.environ["BENCH_BUILD_CACHE"]).expanduser()
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / "monoinstance_bench"


def build_shim(directory: Path | None = None) -> Path | None:
    """The compiled shim (built once, atomically: concurrent builders each write a temporary file and
    rename it); None when no C compiler is available or the build fails."""
    directory = cache_dir() if directory is None else directory
    digest = hashlib.sha256(SHIM_SOURCE.encode()).hexdigest()[:12]
    target = directory / f"{SHIM_STEM}-{digest}.so"
    if target.exists():
        return target
    cc = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        return None
    try:
        directory.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(dir=directory) as tmp:
            src = Path(tmp) / "shim.c"
            src.write_text(SHIM_SOURCE)
            out = Path(tmp) / target.name
            subprocess.run([cc, "-shared", "-fPIC", "-O2", "-o", str(out), str(src)], check=True,
                           stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, timeout=120)
            os.replace(out, target)
    except (OSError, subprocess.SubprocessError):
        return None
    return target


@functools.cache
def shim_loaded() -> bool:
    """Whether the shim is mapped into this process (read from ``/proc/self/maps``, not the environment; once: it
    is preloaded at the start of a process or not at all, and planning asks for every job)."""
    try:
        return SHIM_STEM in Path("/proc/self/maps").read_text()
    except OSError:
        return False


def blas_path() -> str:
    """``"mkl-avx512-shim"`` / ``"mkl-avx2-shim"`` when the shim is loaded (by the CPU's widest extension: the
    path MKL then takes), else ``"default"``: recorded in every job row and in the full job id (only when not
    ``"default"``, so ids from before this switch are unchanged)."""
    if not shim_loaded():
        return "default"
    return f"mkl-{cpu_facts(_read_cpuinfo())[1] or 'generic'}-shim"


def mkl_code_path() -> str:
    """The code path MKL dispatches to in this process (``mkl_serv_cpu_detect``), e.g. ``"AVX-512"``;
    ``"unknown"`` where torch's library does not export it. Imports torch."""
    import ctypes

    import torch

    try:
        lib = ctypes.CDLL(str(Path(torch.__file__).parent / "lib" / "libtorch_cpu.so"))
        detect = lib.mkl_serv_cpu_detect
    except (OSError, AttributeError):
        return "unknown"
    detect.restype = ctypes.c_int
    code = int(detect())
    return MKL_CODE_PATHS.get(code, f"code {code}")


def preload_env(shim: Path, env: dict[str, str] | os._Environ[str]) -> dict[str, str]:
    """A copy of ``env`` with ``shim`` first in ``LD_PRELOAD`` and the loop guard set."""
    new = dict(env)
    rest = [p for p in new.get("LD_PRELOAD", "").replace(":", " ").split() if SHIM_STEM not in p]
    new["LD_PRELOAD"] = " ".join([str(shim), *rest])
    new[ENV_TRIED] = "1"
    return new


def reexec_with_mkl_shim() -> None:
    """Re-execute this command with the shim preloaded when :func:`wants_shim` says so and it is not
    loaded yet; returns (doing nothing) otherwise, also when the shim cannot be built (after a one-line
    note). Call it first thing in an entry point, before torch is imported."""
    if shim_loaded() or os.environ.get(ENV_TRIED) == "1" or not wants_shim(_read_cpuinfo(), os.environ):
        return
    shim = build_shim()
    if shim is None:
        print(f"note: no C compiler: MKL keeps its generic path on this non-Intel CPU ({ENV_SWITCH}=0 silences this)", file=sys.stderr)
        os.environ[ENV_TRIED] = "1"
        return
    argv = list(getattr(sys, "orig_argv", [])) or [sys.executable, *sys.argv]
    sys.stdout.flush()
    sys.stderr.flush()
    os.execve(sys.executable, [sys.executable, *argv[1:]], preload_env(shim, os.environ))
