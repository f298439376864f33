"""``methods.monosdf.float_mode``: FTZ / DAZ reach torch's OpenMP pool threads, not only the calling thread.

torch.set_flush_denormal alone sets the calling thread's mode; a parallel op's other chunks ran with IEEE arithmetic
(a 2-thread step lost most of the flush's gain). The checks use 2 pool threads whatever the machine has
(OpenMP starts them even on one core)."""

from __future__ import annotations

import pytest
import torch

from methods.monosdf import float_mode

pytestmark = pytest.mark.skipif(not float_mode.pool_threads_reached(), reason="C++ extension unavailable")


@pytest.fixture
def two_threads():
    before = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        yield
    finally:
        torch.set_num_threads(before)


def _denormal_survivors() -> int:
    """How many of 2^21 denormal inputs (1e-39) stay non-zero through a parallel elementwise product (ATen splits
    it across the pool threads)."""
    x = torch.full((1 << 21,), 1e-39)
    return int(((x * 1.0) != 0).sum())


def test_flushed_block_reaches_every_pool_thread_and_ieee_returns_after(two_threads):
    assert _denormal_survivors() == 1 << 21  # IEEE: denormals are kept
    with float_mode.denormals_flushed():
        assert float_mode.flush_denormal_per_thread() == [1, 1]
        assert _denormal_survivors() == 0  # every chunk flushed, not only the calling thread's
        small = torch.full((64, 64), 1e-39)
        assert float((small @ torch.eye(64)).abs().max()) == 0.0  # MKL's product too
    assert float_mode.flush_denormal_per_thread() == [0, 0]
    assert _denormal_survivors() == 1 << 21


def test_calling_thread_alone_leaves_the_pool_ieee(two_threads):
    """The failure this module fixes, kept visible: torch's own switch misses the pool's other thread."""
    _denormal_survivors()  # the pool exists before the switch, as in a trainer after its first step
    torch.set_flush_denormal(True)
    try:
        assert float_mode.flush_denormal_per_thread() == [1, 0]
    finally:
        torch.set_flush_denormal(False)


def test_calling_thread_only_when_asked(two_threads):
    """``pool_threads=False`` (the ``fast_grid: false`` twin, which runs without C++): the calling thread only."""
    _denormal_survivors()
    with float_mode.denormals_flushed(pool_threads=False):
        assert float_mode.flush_denormal_per_thread() == [1, 0]
    assert float_mode.flush_denormal_per_thread() == [0, 0]


def test_off_is_a_no_op(two_threads):
    with float_mode.denormals_flushed(False):
        assert float_mode.flush_denormal_per_thread() == [0, 0]
        assert _denormal_survivors() == 1 << 21
