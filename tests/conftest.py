"""Shared test setup: a temporary dataset cache and the tiny scenes that several test folders load.

Dataset cache. ``bench.data.datasets.DEFAULT_CACHE`` is read from the environment variable
``BENCH_CACHE`` when ``bench`` is first imported, so it is set here, at the top of the top-level
conftest (pytest imports it before any test module or lower conftest). Unless it is already exported,
the suite synthesises its datasets into a fresh temporary folder that is removed at the end of the
session: tests never write into ``results/`` of the checkout. To keep one cache across sessions (the
tiny datasets take a few seconds each to synthesise), export it:

    BENCH_CACHE=/tmp/bench-cache .venv/bin/python -m pytest -q -m "not slow"

(an exported cache is used as it is and never removed; dataset folders are keyed by recipe hash and
code version, so a stale entry is never reused). Subprocesses started by tests (the CLI, Dask workers)
inherit it.

Shared scenes. ``tiny_scene`` (``configs/scenes/scannet_like_tiny.yaml``) and ``llff_tiny_scene``
(``llff_like_0``), both at the ``tiny`` scale, are loaded once per session and shared by every test
that asks for them, so no test may change them: derive a variant with ``dataclasses.replace`` and
copied arrays. A session-end check fails (an error at teardown) if a shared scene was changed.
"""

from __future__ import annotations

import os
import shutil
import sys
import tempfile

_TMP_CACHE: str | None = None  # the temporary cache this session made (removed at its end), None if exported
if not os.environ.get("BENCH_CACHE"):
    _TMP_CACHE = tempfile.mkdtemp(prefix="bench-test-cache-")
    os.environ["BENCH_CACHE"] = _TMP_CACHE

if "bench.data.datasets" in sys.modules:  # imported before this conftest (a plugin?): its cache is the repo's
    raise RuntimeError("bench.data.datasets was imported before tests/conftest.py set BENCH_CACHE; "
                       f"its DEFAULT_CACHE is {sys.modules['bench.data.datasets'].DEFAULT_CACHE}")

import dataclasses  # noqa: E402
import hashlib  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402


def pytest_unconfigure(config) -> None:
    if _TMP_CACHE is not None:
        shutil.rmtree(_TMP_CACHE, ignore_errors=True)


def pytest_collection_modifyitems(config, items) -> None:
    """``nightly`` tests run only when the ``-m`` expression names them (``-m nightly``). A ``-m`` given on
    the command line replaces the ``-m 'not nightly'`` of pyproject's addopts, so without this the fast
    loop ``-m "not slow"`` would run the nightly regression too."""
    if "nightly" in (config.getoption("markexpr") or ""):
        return
    nightly = [item for item in items if item.get_closest_marker("nightly") is not None]
    if nightly:
        config.hook.pytest_deselected(items=nightly)
        items[:] = [item for item in items if item.get_closest_marker("nightly") is None]


def _fingerprint(scene) -> str:
    """Hash of every field of a Scene (array bytes, dtypes and shapes; the repr of everything else)."""
    h = hashlib.sha256()

    def feed(value) -> None:
        if isinstance(value, np.ndarray):
            h.update(f"{value.dtype}{value.shape}".encode())
            h.update(np.ascontiguousarray(value).tobytes())
        elif isinstance(value, dict):
            for k in sorted(value, key=repr):
                h.update(repr(k).encode())
                feed(value[k])
        elif isinstance(value, (list, tuple)):
            h.update(f"{type(value).__name__}{len(value)}".encode())
            for v in value:
                feed(v)
        else:
            h.update(repr(value).encode())

    for f in dataclasses.fields(scene):
        h.update(f.name.encode())
        feed(getattr(scene, f.name))
    return h.hexdigest()


def _shared_scene(name: str, scale: str = "tiny"):
    from bench.data.datasets import load_dataset

    scene = load_dataset(name, scale)
    before = _fingerprint(scene)
    yield scene
    assert _fingerprint(scene) == before, (f"the session-wide scene {name!r} ({scale}) was changed by a test: "
                                           "derive a copy (dataclasses.replace with copied arrays) instead")


@pytest.fixture(scope="session")
def tiny_scene():
    """The earlier scannet_like_tiny (``legacy/scannet_like_tiny``: plain room, camera loop, the legacy
    sim-omnidata profile) at the tiny scale, loaded once per session; read-only by convention (checked).
    The method tests' measured floors (association ARI, uncertainty ranking, the mask term's colour gap)
    rest on this frozen scene; the shipped scannet_like_tiny is what the tables' end-to-end tests run."""
    yield from _shared_scene("legacy/scannet_like_tiny")


@pytest.fixture(scope="session")
def llff_tiny_scene():
    """llff_like_0 at the tiny scale (its images_N copy), loaded once per session; read-only (checked)."""
    yield from _shared_scene("llff_like_0")


@pytest.fixture(scope="session")
def load_script():
    """``load_script("name")``: the module ``scripts/name.py`` (scripts are not a package), loaded once."""
    import importlib.util
    from pathlib import Path

    cache: dict[str, object] = {}

    def load(name: str):
        if name not in cache:
            path = Path(__file__).resolve().parents[1] / "scripts" / f"{name}.py"
            spec = importlib.util.spec_from_file_location(name, path)
            module = importlib.util.module_from_spec(spec)
            spec.loader.exec_module(module)
            cache[name] = module
        return cache[name]

    return load
