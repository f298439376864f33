"""Float32 denormal handling for training steps (``flush_denormals``, config; docs/studies/monosdf-speed.md).

Arithmetic on denormal floats (|x| < 1.18e-38) takes a slow microcode path on x86; a sharp SDF field produces them
in the backward of its MLP (softplus slopes sigmoid(100 z) below e^-87). Flush-to-zero / denormals-are-zero
(FTZ / DAZ) turns them into 0, changing values only below 1.2e-38.

The mode is a per-thread register (MXCSR). ``torch.set_flush_denormal`` sets it in the calling thread only, so
the OpenMP pool that runs ATen's parallel ops and MKL's matrix products kept IEEE arithmetic and a 2-thread step
lost most of the gain. :func:`denormals_flushed` sets it in the calling thread and in every pool
thread (through the C++ extension, ``_float_mode.cpp``); where the extension is unavailable it falls back to the
calling thread only (:func:`pool_threads_reached` says which).
"""

from __future__ import annotations

import contextlib
from typing import Iterator

import torch

from methods.monosdf.grid import _load_extension


def set_flush_denormal(on: bool, pool_threads: bool = True) -> bool:
    """FTZ / DAZ on or off in the calling thread and, through the extension (``pool_threads``), in every OpenMP pool
    thread. ``pool_threads=False``: the calling thread only, and the C++ extension is not compiled for it (the
    ``fast_grid: false`` twin runs without C++).

    Returns True when the pool threads were reached, False when only the calling thread was (not asked, no
    extension, or no MXCSR on this CPU)."""
    torch.set_flush_denormal(on)
    ext = _load_extension() if pool_threads else None
    return bool(ext is not None and ext.set_flush_denormal_all_threads(on))


def flush_denormal_per_thread() -> list[int]:
    """Per OpenMP pool thread (index = thread number, ``omp_get_max_threads()`` entries): 1 if FTZ and DAZ are set,
    0 if not, -1 if unknown (no extension / no MXCSR). For tests and diagnostics."""
    ext = _load_extension()
    if ext is None:
        return [-1] * torch.get_num_threads()
    return [int(m) for m in ext.flush_denormal_per_thread()]


def pool_threads_reached() -> bool:
    """Whether :func:`set_flush_denormal` reaches the pool threads on this machine (the extension compiled)."""
    return _load_extension() is not None


@contextlib.contextmanager
def denormals_flushed(on: bool = True, pool_threads: bool = True) -> Iterator[None]:
    """FTZ / DAZ in every compute thread while the block runs (``on``; a no-op when False), IEEE after it;
    ``pool_threads=False``: in the calling thread only (:func:`set_flush_denormal`).

    The mode is reset to IEEE rather than restored (torch has no call that reads it): left on process-wide, scipy's
    ``cKDTree.query_ball_point`` in a later DTU evaluation crashed (segfault in CI)."""
    if not on:
        yield
        return
    set_flush_denormal(True, pool_threads)
    try:
        yield
    finally:
        set_flush_denormal(False, pool_threads)
