"""Compile-on-first-use C++ extensions of the methods, with a build lock that survives killed builds.

Every C++ kernel of the project (``methods/monosdf``'s grid, encoding and float-mode kernels,
``methods/gaussians``' rasteriser) is built by ``torch.utils.cpp_extension.load`` the first time a process
needs it, cached in ``~/.cache/torch_extensions`` (or ``TORCH_EXTENSIONS_DIR``), and is optional: without a
compiler :meth:`CppExtension.load` warns once and returns None, and the callers take their PyTorch twin.
"""

from __future__ import annotations

import contextlib
import os
import threading
import time
from pathlib import Path
from types import ModuleType
from typing import Iterator

BUILD_LOCK_TIMEOUT_S = float(os.environ.get("BENCH_BUILD_LOCK_TIMEOUT", "900"))


@contextlib.contextmanager
def build_lock(build_dir: Path, timeout_s: float = BUILD_LOCK_TIMEOUT_S) -> Iterator[None]:
    """Hold an exclusive ``flock`` on ``build_dir/bench-build.lock`` while torch builds / loads a kernel.

    torch's own build lock is a plain file (``build_dir/lock``) that a killed build leaves behind, after
    which every later build waits for it forever. The kernel releases a ``flock`` when its holder dies,
    so while we hold ours no other bench process is building: a torch ``lock`` file found then is stale
    and is removed. Waits at most ``timeout_s`` for a live build of another process, then raises
    ``TimeoutError`` naming the lock file.
    """
    import fcntl

    build_dir.mkdir(parents=True, exist_ok=True)
    path = build_dir / "bench-build.lock"
    with open(path, "a+") as fh:
        deadline = time.monotonic() + timeout_s
        while True:
            try:
                fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except BlockingIOError:
                if time.monotonic() > deadline:
                    raise TimeoutError(f"{path}: another process has been building the C++ kernel for over "
                                       f"{timeout_s:.0f} s (BENCH_BUILD_LOCK_TIMEOUT)") from None
                time.sleep(0.5)
        try:
            (build_dir / "lock").unlink(missing_ok=True)  # a dead build's torch lock: nobody else is building
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


class CppExtension:
    """One C++ extension: its name, sources (next to ``anchor``) and compiler flags; loaded once per process.

    Args:
        name: extension (module) name; also its build folder's name.
        anchor: a file in the folder that holds the sources (pass ``__file__``).
        sources: source file names in that folder.
        cflags, ldflags: extra compiler / linker flags.
    """

    def __init__(self, name: str, anchor: str, sources: tuple[str, ...], cflags: tuple[str, ...], ldflags: tuple[str, ...] = ()) -> None:
        self.name = name
        self.sources = tuple(str(Path(anchor).with_name(s)) for s in sources)
        self.cflags = list(cflags)
        self.ldflags = list(ldflags)
        self._module: ModuleType | None = None
        self._failed = False
        self._lock = threading.Lock()

    def load(self) -> ModuleType | None:
        """Compile (first use) and load the extension; None, with one warning, if it cannot be built."""
        if self._module is not None or self._failed:
            return self._module
        with self._lock:
            if self._module is None and not self._failed:
                try:
                    from torch.utils.cpp_extension import _get_build_directory, load

                    verbose = os.environ.get("BENCH_VERBOSE_BUILD") == "1"
                    with build_lock(Path(_get_build_directory(self.name, verbose))):
                        self._module = load(name=self.name, sources=list(self.sources), extra_cflags=self.cflags,
                                            extra_ldflags=self.ldflags, verbose=verbose)
                except Exception as exc:  # no compiler / headers: the callers use their PyTorch twin
                    import warnings

                    warnings.warn(f"C++ kernel {self.name} unavailable ({exc}); using the pure-PyTorch path")
                    self._failed = True
        return self._module
