"""``methods.cpp_build``: kernel build folders keyed by sources and flags (shared by every checkout, never
rebuilt by another one), the notices while a kernel compiles or waits, and the build time training leaves out."""

from __future__ import annotations

import fcntl
import os
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from methods.cpp_build import CppExtension, OwnClock, build_lock, build_seconds

REPO = Path(__file__).resolve().parents[2]
BROKEN = "this is not C++\n"  # fails in the compiler's first line: a build that is cheap to attempt


def _checkout(root: Path, text: str = BROKEN) -> Path:
    """A folder standing for one checkout's kernel sources; returns the anchor file beside them."""
    root.mkdir(parents=True)
    (root / "_k.cpp").write_text(text)
    return root / "anchor.py"


def test_the_build_folder_depends_on_sources_and_flags_not_on_the_checkout(tmp_path: Path, monkeypatch):
    monkeypatch.setenv("TORCH_EXTENSIONS_DIR", str(tmp_path / "ext"))
    a = CppExtension("probe_kernel", str(_checkout(tmp_path / "clone a")), ("_k.cpp",), ("-O2",))
    b = CppExtension("probe_kernel", str(_checkout(tmp_path / "wörktree b")), ("_k.cpp",), ("-O2",))
    assert a.build_dir() == b.build_dir() and a.build_dir().name.startswith("probe_kernel-")
    assert "clone" not in str(a.build_dir())
    edited = CppExtension("probe_kernel", str(_checkout(tmp_path / "c", BROKEN + "//\n")), ("_k.cpp",), ("-O2",))
    other_flags = CppExtension("probe_kernel", str(_checkout(tmp_path / "d")), ("_k.cpp",), ("-O3",))
    assert len({a.build_dir(), edited.build_dir(), other_flags.build_dir()}) == 3


def test_a_compile_says_so_on_stderr_and_counts_as_build_time(tmp_path: Path, monkeypatch, capfd):
    monkeypatch.setenv("TORCH_EXTENSIONS_DIR", str(tmp_path / "ext"))
    ext = CppExtension("probe_kernel", str(_checkout(tmp_path / "src")), ("_k.cpp",), ("-O1",), ("-lm",))
    folder = ext.build_dir()
    before, clock = build_seconds(), OwnClock()
    with pytest.warns(UserWarning, match=r"C\+\+ kernel probe_kernel unavailable"):
        assert ext.load() is None
    err = capfd.readouterr().err
    assert err.count("compiling the C++ kernel probe_kernel (first use, ~2 min)") == 1
    assert build_seconds() > before and abs(clock.seconds()) < 0.05  # the compile is not the clock's time
    assert (ext.build_dir() / "src" / "_k.cpp").read_text() == BROKEN  # compiled from the build folder's copy
    assert ext.build_dir() == folder  # torch appends to the flag lists it gets: the extension's own are unchanged
    assert ext.load() is None  # once per process: no second attempt, no second notice
    assert "compiling" not in capfd.readouterr().err


def test_a_build_held_by_another_process_is_waited_for_with_one_notice(tmp_path: Path, capfd):
    with open(tmp_path / "bench-build.lock", "a+") as held:
        fcntl.flock(held, fcntl.LOCK_EX)
        threading.Timer(1.2, lambda: fcntl.flock(held, fcntl.LOCK_UN)).start()
        t = time.perf_counter()
        with build_lock(tmp_path, timeout_s=30, label="probe_kernel"):
            waited = time.perf_counter() - t
    assert waited >= 1.0
    assert capfd.readouterr().err.count("waiting for another process compiling the C++ kernel probe_kernel") == 1


@pytest.mark.slow
def test_a_second_checkout_loads_the_first_ones_kernel_without_rebuilding(tmp_path: Path):
    """The kernel built by this checkout (the test session's TORCH_EXTENSIONS_DIR) is loaded by a copy of the
    tree elsewhere, as a clone or a ``git worktree`` would: no compile, no change to the built library."""
    from methods.monosdf.grid import _KERNEL, fast_available

    if not fast_available():
        pytest.skip("no C++ compiler")
    library = _KERNEL.build_dir() / f"{_KERNEL.name}.so"
    stamp = library.stat().st_mtime_ns
    clone = tmp_path / "other checkout"
    for pkg in ("bench", "methods", "metrics"):
        shutil.copytree(REPO / pkg, clone / pkg, ignore=shutil.ignore_patterns("__pycache__"))
    code = ("import sys; from methods.monosdf.grid import _KERNEL, _load_extension; "
            "sys.exit(0 if _load_extension() is not None and _KERNEL.sources[0].is_relative_to(sys.argv[1]) else 3)")
    t = time.perf_counter()
    res = subprocess.run([sys.executable, "-c", code, str(clone)], cwd=clone, timeout=600, capture_output=True, text=True,
                         env={**os.environ, "PYTHONPATH": str(clone)})
    assert res.returncode == 0, res.stderr[-2000:]
    assert "compiling" not in res.stderr and library.stat().st_mtime_ns == stamp
    assert time.perf_counter() - t < 60  # a load, not a 2-minute build
    # the build compiles its own copies of the sources, never a checkout's (torch's include paths may lie in a
    # checkout, e.g. a .venv inside it, and are the same for every checkout that shares the environment)
    assert str(REPO / "methods") not in (_KERNEL.build_dir() / "build.ninja").read_text()
