"""MKL's Intel code paths (AVX-512 or AVX2) on a non-Intel CPU (bench/mkl_dispatch.py): when they are taken, and
that they compute what MKL's generic path computes (the slow twin), on matrix products and on whole MonoSDF
training steps."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from bench import mkl_dispatch as md

ROOT = Path(__file__).resolve().parents[2]

AMD_AVX512 = "processor\t: 0\nvendor_id\t: AuthenticAMD\nflags\t\t: fpu sse2 avx2 fma avx512f avx512dq avx512bw\n\nprocessor\t: 1\n"
AMD_AVX2 = "processor\t: 0\nvendor_id\t: AuthenticAMD\nflags\t\t: fpu sse2 avx2 fma\n"
AMD_AVX = "processor\t: 0\nvendor_id\t: AuthenticAMD\nflags\t\t: fpu sse2 avx\n"
INTEL_AVX512 = "processor\t: 0\nvendor_id\t: GenuineIntel\nflags\t\t: fpu sse2 avx2 fma avx512f\n"


def test_the_shim_is_wanted_only_on_a_non_intel_cpu_with_avx512_or_avx2_on_linux() -> None:
    assert md.cpu_facts(AMD_AVX512) == ("AuthenticAMD", "avx512")
    assert md.cpu_facts(AMD_AVX2) == ("AuthenticAMD", "avx2")
    assert md.cpu_facts(AMD_AVX) == ("AuthenticAMD", "")
    assert md.wants_shim(AMD_AVX512, {}, platform="linux")
    assert md.wants_shim(AMD_AVX2, {}, platform="linux")              # MKL's AVX2 path instead of the generic one
    assert not md.wants_shim(AMD_AVX2, {md.ENV_SWITCH: "0"}, platform="linux")
    assert not md.wants_shim(AMD_AVX, {}, platform="linux")           # no Intel path worth taking
    assert not md.wants_shim(INTEL_AVX512, {}, platform="linux")      # MKL takes it by itself
    assert not md.wants_shim(AMD_AVX512, {md.ENV_SWITCH: "0"}, platform="linux")
    assert not md.wants_shim(AMD_AVX512, {}, platform="darwin")       # no LD_PRELOAD there
    assert not md.wants_shim("", {}, platform="linux")                # unreadable cpuinfo: do nothing


def test_preload_env_puts_the_shim_first_once_and_keeps_other_preloads(tmp_path: Path) -> None:
    shim = tmp_path / f"{md.SHIM_STEM}-abc.so"
    env = md.preload_env(shim, {"LD_PRELOAD": "/lib/other.so", "PATH": "/bin"})
    assert env["LD_PRELOAD"] == f"{shim} /lib/other.so"
    assert env[md.ENV_TRIED] == "1" and env["PATH"] == "/bin"
    again = md.preload_env(shim, env)
    assert again["LD_PRELOAD"] == f"{shim} /lib/other.so"


@pytest.mark.skipif(shutil.which("cc") is None and shutil.which("gcc") is None, reason="no C compiler")
def test_build_shim_builds_once_into_the_cache(tmp_path: Path) -> None:
    first = md.build_shim(tmp_path)
    assert first is not None and first.exists() and first.name.startswith(md.SHIM_STEM)
    mtime = first.stat().st_mtime_ns
    assert md.build_shim(tmp_path) == first and first.stat().st_mtime_ns == mtime
    assert [p.name for p in tmp_path.iterdir()] == [first.name]  # no temporary file left behind


def test_build_shim_without_a_compiler_returns_none(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("CC", str(tmp_path / "no-such-compiler"))
    assert md.build_shim(tmp_path) is None
    assert list(tmp_path.iterdir()) == []


# ---------------------------------------------------------------------------------------------------------
# the two paths in fresh processes (the shim can only be loaded at process start)

PROBE = r"""
import json, sys, torch
from bench.mkl_dispatch import blas_path, mkl_code_path, reexec_with_mkl_shim
reexec_with_mkl_shim()
torch.set_num_threads(1)
g = torch.Generator().manual_seed(0)
out = {"blas": blas_path(), "mkl": mkl_code_path(), "products": []}
for k, n in [(55, 32), (32, 32), (32, 16), (300, 200)]:
    x, w = torch.randn(4096, k, generator=g), torch.randn(k, n, generator=g)
    out["products"].append([(x @ w).tolist(), (x.t() @ (x @ w)).tolist()])
if sys.argv[1] == "step":
    from bench.data.datasets import load_dataset
    from methods.monosdf.trainer import MonoSDFTrainer
    from methods.registry import typed_method_config
    scene = load_dataset("scannet_like_tiny", "tiny")
    trainer = MonoSDFTrainer(scene, typed_method_config("monosdf", "tiny", {}), seed=0)
    out["losses"] = [trainer.step() for _ in range(3)]
print("JSON" + json.dumps(out))
"""


def _probe(switch: str, what: str) -> dict:
    env = {**os.environ, md.ENV_SWITCH: switch, "PYTHONPATH": str(ROOT)}
    env.pop(md.ENV_TRIED, None)
    done = subprocess.run([sys.executable, "-c", PROBE, what], env=env, capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert done.returncode == 0, done.stderr[-3000:]
    line = [ln for ln in done.stdout.splitlines() if ln.startswith("JSON")][-1]
    return json.loads(line[4:])


needs_shim = pytest.mark.skipif(not md.wants_shim(md._read_cpuinfo(), {}) or md.build_shim() is None,
                                reason="MKL's switch applies only on a non-Intel Linux CPU with AVX-512 or AVX2 and a C compiler")
SIMD = md.cpu_facts(md._read_cpuinfo())[1]  # this machine's: the path the shim must give
MKL_NAME = {"avx512": "AVX-512", "avx2": "AVX2"}.get(SIMD, "?")


@needs_shim
@pytest.mark.slow
def test_the_intel_path_is_taken_and_gives_the_generic_paths_products() -> None:
    import numpy as np

    generic, fast = _probe("0", "products"), _probe("1", "products")
    assert generic["blas"] == "default" and fast["blas"] == f"mkl-{SIMD}-shim"
    assert fast["mkl"] == MKL_NAME and generic["mkl"] != MKL_NAME  # the switch changes MKL's dispatch, measured in-process
    for (a0, b0), (a1, b1) in zip(generic["products"], fast["products"]):
        for p, q in ((a0, a1), (b0, b1)):
            p, q = np.asarray(p), np.asarray(q)
            scale = np.abs(p).max()
            assert np.abs(p - q).max() <= 1e-5 * scale  # the same products up to float32 rounding


@needs_shim
@pytest.mark.slow
def test_monosdf_steps_on_the_intel_path_match_the_generic_path() -> None:
    generic, fast = _probe("0", "step"), _probe("1", "step")
    assert len(generic["losses"]) == len(fast["losses"]) == 3
    for step, (l0, l1) in enumerate(zip(generic["losses"], fast["losses"])):
        assert set(l0) == set(l1)
        for key in l0:
            a, b = float(l0[key]), float(l1[key])
            tol = 2e-5 * max(abs(a), 1e-3)  # rounding only: measured <= 3e-7 relative over the 3 steps (Zen 5 AVX-512; Zen 3 AVX2: 2.4e-7)
            assert abs(a - b) <= tol, (step, key, a, b)


def test_the_blas_path_enters_the_full_job_id_only_when_not_the_default(monkeypatch: pytest.MonkeyPatch) -> None:
    from bench.jobs import JobPlan
    from bench.runner import job_id_for
    from methods.registry import method_config

    plan = JobPlan("t", "oracle", "oracle_tsdf", {}, "scannet", "scannet", "scannet", "scannet_like_tiny", 0, "tiny")
    cfg = method_config("oracle_tsdf", "tiny")
    monkeypatch.setattr(md, "blas_path", lambda: "default")
    base, full = job_id_for(plan, cfg), job_id_for(plan, cfg, threads=1)
    monkeypatch.setattr(md, "blas_path", lambda: "mkl-avx512-shim")
    assert job_id_for(plan, cfg) == base                # tables and reports match rows by this one: unchanged
    assert job_id_for(plan, cfg, threads=1) != full     # a row from the other path is not silently reused


@needs_shim
@pytest.mark.slow
def test_the_bench_command_reexecutes_itself_onto_the_intel_path() -> None:
    """End to end: the console script re-executes itself with the shim, and the off switch keeps MKL's generic path."""
    bench = Path(sys.executable).with_name("bench")
    if not bench.exists():
        pytest.skip("the bench console script is not installed beside this interpreter")
    for switch, expected in (("1", f"MKL {MKL_NAME} path (blas: mkl-{SIMD}-shim"), ("0", "(blas: default")):
        env = {**os.environ, md.ENV_SWITCH: switch}
        env.pop(md.ENV_TRIED, None)
        env.pop("LD_PRELOAD", None)
        done = subprocess.run([str(bench), "list"], env=env, capture_output=True, text=True, timeout=300, cwd=ROOT)
        assert done.returncode == 0, done.stderr[-2000:]
        assert expected in done.stdout.splitlines()[-1], done.stdout[-500:]
