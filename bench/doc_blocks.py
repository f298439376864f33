"""Generated blocks inside hand-written markdown: the text between a ``begin`` and an ``end`` marker line is
written by a generator and checked by a test, the rest of the document is prose.

Used by the README's results at a glance (:mod:`bench.glance`) and by the method pages' parameter tables
(``scripts/method_parameters.py``).
"""

from __future__ import annotations

from pathlib import Path

from bench.data.errors import BenchInputError


def _span(document: str, begin: str, end: str, where: str | Path) -> tuple[int, int]:
    """Where the block's text starts (after the ``begin`` line) and ends (at the ``end`` line)."""
    start = document.find(begin)
    stop = document.find(end, start) if start >= 0 else -1  # the first end after this begin: blocks may share it
    if stop < 0:
        raise BenchInputError(where, f"no generated block: expected the lines {begin!r} and {end!r}, in that order")
    return start + len(begin) + 1, stop


def replace_block(document: str, block: str, begin: str, end: str, where: str | Path) -> str:
    """``document`` with the text between the markers replaced by ``block``; BenchInputError naming ``where``
    when the markers are missing or out of order."""
    start, stop = _span(document, begin, end, where)
    return document[:start] + block + document[stop:]


def current_block(document: str, begin: str, end: str, where: str | Path) -> str:
    """The text between the markers (what :func:`replace_block` replaces)."""
    start, stop = _span(document, begin, end, where)
    return document[start:stop]
