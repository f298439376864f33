"""Compile-on-first-use C++ extensions of the methods, in build folders keyed by what decides the binary.

Every C++ kernel of the project (``methods/monosdf``'s grid, encoding and float-mode kernels,
``methods/gaussians``' rasteriser) is built by ``torch.utils.cpp_extension.load`` the first time a process
needs it and is optional: without a compiler :meth:`CppExtension.load` warns once and returns None, and
the callers take their PyTorch twin.

Build folder: ``<torch extensions root>/<name>-<digest>`` (root: ``TORCH_EXTENSIONS_DIR`` or
``~/.cache/torch_extensions/py3XX_cpu``), where the digest covers the sources' names and bytes, the
compiler and linker flags, the torch version and, with ``-march=native``, the CPU's instruction-set
flags (:func:`build_digest`). The sources are copied into the folder and compiled from there, so the
folder's ``build.ninja`` holds no path of the checkout: every checkout (clone, ``git worktree``) with the
same sources shares one build, and a checkout with other sources gets its own folder. Neither rebuilds
the other's kernel.

While a kernel compiles, one line on stderr says so; time spent in :meth:`CppExtension.load` (waiting for
another process's build, compiling, loading) adds to :func:`build_seconds`, which training timers
subtract so that a stage's time is its own training (:class:`OwnClock`).
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import platform
import sys
import threading
import time
from pathlib import Path
from types import ModuleType
from typing import Iterator

BUILD_LOCK_TIMEOUT_S = float(os.environ.get("BENCH_BUILD_LOCK_TIMEOUT", "900"))
CPUINFO = Path("/proc/cpuinfo")

_build_seconds = 0.0
_build_seconds_lock = threading.Lock()


def build_seconds() -> float:
    """Seconds this process has spent so far loading C++ kernels (waiting for a lock, compiling, loading);
    a timer of training work subtracts the part that fell inside its interval."""
    return _build_seconds


class OwnClock:
    """A wall clock of some work that leaves out the kernel builds inside it (:func:`build_seconds`): a stage
    whose first step waited minutes for a compile books its training time only."""

    def __init__(self) -> None:
        self._wall = time.perf_counter()
        self._builds = build_seconds()

    def seconds(self) -> float:
        """Wall seconds since the clock started, minus the kernel-build seconds in between."""
        return (time.perf_counter() - self._wall) - (build_seconds() - self._builds)


def _add_build_seconds(seconds: float) -> None:
    global _build_seconds
    with _build_seconds_lock:
        _build_seconds += seconds


def _notice(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


@contextlib.contextmanager
def build_lock(build_dir: Path, timeout_s: float = BUILD_LOCK_TIMEOUT_S, label: str | None = None) -> Iterator[None]:
    """Hold an exclusive ``flock`` on ``build_dir/bench-build.lock`` while torch builds / loads a kernel.

    torch's own build lock is a plain file (``build_dir/lock``) that a killed build leaves behind, after
    which every later build waits for it forever. The kernel releases a ``flock`` when its holder dies,
    so while we hold ours no other bench process is building: a torch ``lock`` file found then is stale
    and is removed. Waits at most ``timeout_s`` for a live build of another process (saying so once on
    stderr when ``label`` names the kernel), then raises ``TimeoutError`` naming the lock file.
    """
    import fcntl

    build_dir.mkdir(parents=True, exist_ok=True)
    path = build_dir / "bench-build.lock"
    with open(path, "a+") as fh:
        deadline = time.monotonic() + timeout_s
        told = False
        while True:
            try:
                fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except BlockingIOError:
                if time.monotonic() > deadline:
                    raise TimeoutError(f"{path}: another process has been building the C++ kernel for over "
                                       f"{timeout_s:.0f} s (BENCH_BUILD_LOCK_TIMEOUT)") from None
                if label and not told:
                    _notice(f"waiting for another process compiling the C++ kernel {label} ({path})...")
                    told = True
                time.sleep(0.5)
        try:
            (build_dir / "lock").unlink(missing_ok=True)  # a dead build's torch lock: nobody else is building
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def _cpu_flags() -> str:
    """The instruction-set flags of this machine's CPU (``/proc/cpuinfo``), what ``-march=native`` compiles for."""
    try:
        for line in CPUINFO.read_text().splitlines():
            if line.startswith("flags"):
                return " ".join(sorted(line.partition(":")[2].split()))
    except OSError:
        pass
    return platform.processor()


def build_digest(sources: list[Path], cflags: tuple[str, ...], ldflags: tuple[str, ...]) -> str:
    """16-hex SHA-256 of what decides a kernel's binary: source names and bytes, flags, the torch version,
    the machine and (``-march=native``) the CPU flags. Not the sources' folder: checkouts share builds."""
    import torch

    h = hashlib.sha256()
    for src in sources:
        h.update(src.name.encode() + b"\0")
        h.update(src.read_bytes() + b"\0")
    h.update(repr((tuple(cflags), tuple(ldflags), torch.__version__, platform.machine())).encode())
    if "-march=native" in cflags:
        h.update(_cpu_flags().encode())
    return h.hexdigest()[:16]


def _copy_sources(sources: list[Path], folder: Path) -> list[str]:
    """Copy ``sources`` into ``folder`` (atomically, only those not there yet: the folder is keyed by their
    bytes); the copies' paths, what the build compiles."""
    folder.mkdir(parents=True, exist_ok=True)
    out = []
    for src in sources:
        dst = folder / src.name
        if not dst.exists():
            tmp = folder / f".{src.name}.{os.getpid()}.tmp"
            tmp.write_bytes(src.read_bytes())
            os.replace(tmp, dst)
        out.append(str(dst))
    return out


class CppExtension:
    """One C++ extension: its name, sources (next to ``anchor``) and compiler flags; loaded once per process.

    Args:
        name: extension (module) name; with :func:`build_digest`, its build folder's name.
        anchor: a file in the folder that holds the sources (pass ``__file__``).
        sources: source file names in that folder.
        cflags, ldflags: extra compiler / linker flags.
    """

    def __init__(self, name: str, anchor: str, sources: tuple[str, ...], cflags: tuple[str, ...], ldflags: tuple[str, ...] = ()) -> None:
        self.name = name
        self.sources = tuple(Path(anchor).with_name(s) for s in sources)
        self.cflags = tuple(cflags)
        self.ldflags = tuple(ldflags)
        self._module: ModuleType | None = None
        self._failed = False
        self._lock = threading.Lock()

    def build_dir(self) -> Path:
        """The build folder of these sources and flags (created): ``<extensions root>/<name>-<digest>``."""
        from torch.utils.cpp_extension import _get_build_directory

        digest = build_digest(list(self.sources), self.cflags, self.ldflags)
        return Path(_get_build_directory(f"{self.name}-{digest}", False))

    def load(self) -> ModuleType | None:
        """Compile (first use) and load the extension; None, with one warning, if it cannot be built."""
        if self._module is not None or self._failed:
            return self._module
        with self._lock:
            if self._module is None and not self._failed:
                t = time.perf_counter()
                try:
                    self._module = self._build_and_import()
                except Exception as exc:  # no compiler / headers: the callers use their PyTorch twin
                    import warnings

                    warnings.warn(f"C++ kernel {self.name} unavailable ({exc}); using the pure-PyTorch path")
                    self._failed = True
                finally:
                    _add_build_seconds(time.perf_counter() - t)
        return self._module

    def _build_and_import(self) -> ModuleType:
        from torch.utils.cpp_extension import load

        verbose = os.environ.get("BENCH_VERBOSE_BUILD") == "1"
        folder = self.build_dir()
        with build_lock(folder, label=self.name):
            if not (folder / f"{self.name}.so").exists():
                _notice(f"compiling the C++ kernel {self.name} (first use, ~2 min) in {folder} ...")
            sources = _copy_sources(list(self.sources), folder / "src")
            # copies: torch appends its own flags to the lists it is given (the digest would change after a load)
            return load(name=self.name, sources=sources, extra_cflags=list(self.cflags), extra_ldflags=list(self.ldflags),
                        build_directory=str(folder), verbose=verbose)
