"""A built wheel carries every C++ source, and both C++ paths load from a non-editable install.

The kernels are compiled on first use from sources next to their Python modules
(``methods.cpp_build.CppExtension``), so a wheel without a ``.cpp`` does not fail: it falls back to the
PyTorch twin with one warning, and the two rasterisers differ by float rounding. These tests build the
wheel from a copy of the sources, install it into a folder of its own and load the kernels from there
(the build folders are keyed by source bytes and flags, not by checkout, so a warm cache is reused).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("bench", "methods", "metrics")

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A wheel of the project, built from a copy of its packaging inputs (the checkout stays clean)."""
    src = tmp_path_factory.mktemp("src")
    for name in ("pyproject.toml", "README.md"):
        shutil.copy2(ROOT / name, src / name)
    for pkg in PACKAGES:
        shutil.copytree(ROOT / pkg, src / pkg, ignore=shutil.ignore_patterns("__pycache__"))
    out = tmp_path_factory.mktemp("dist")
    done = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
                           "--disable-pip-version-check", "-w", str(out), str(src)], capture_output=True, text=True)
    assert done.returncode == 0, f"pip wheel failed:\n{done.stdout}\n{done.stderr}"
    (whl,) = out.glob("*.whl")
    return whl


def test_the_wheel_holds_every_cpp_source_of_the_packages(wheel: Path):
    expected = {p.relative_to(ROOT).as_posix() for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.cpp")}
    assert expected, "no C++ source found: the test would prove nothing"
    with zipfile.ZipFile(wheel) as zf:
        packed = {n for n in zf.namelist() if n.endswith(".cpp")}
    assert expected <= packed, f"missing from the wheel: {sorted(expected - packed)}"


def test_both_cpp_paths_load_from_an_installed_wheel(wheel: Path, tmp_path: Path):
    target = tmp_path / "site"
    done = subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--disable-pip-version-check",
                           "--target", str(target), str(wheel)], capture_output=True, text=True)
    assert done.returncode == 0, f"pip install failed:\n{done.stdout}\n{done.stderr}"
    probe = (
        "import warnings; warnings.simplefilter('error')\n"
        "import methods, methods.monosdf.grid as g, methods.gaussians.raster_kernel as r\n"
        "print(methods.__file__)\n"
        "assert g.fast_available(), 'grid kernel did not load'\n"
        "assert r.raster_kernel_available(), 'raster kernel did not load'\n"
    )
    env = {**os.environ, "PYTHONPATH": str(target)}
    run = subprocess.run([sys.executable, "-c", probe], cwd=tmp_path, env=env, capture_output=True, text=True)
    assert run.returncode == 0, f"{run.stdout}\n{run.stderr}"
    assert Path(run.stdout.strip().splitlines()[-1]).is_relative_to(target), "imported the checkout, not the installed wheel"
