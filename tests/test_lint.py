"""Static checks as tests, so CI runs them: ``ruff check`` (rules in pyproject's [tool.ruff]) over the
repository and ``mypy`` (settings and the checked packages in [tool.mypy]) must both pass.

Run them by hand from the repository root: ``.venv/bin/python -m ruff check .`` and
``.venv/bin/python -m mypy``. mypy is ``slow``: about a minute without its cache (``.mypy_cache``),
a few seconds with it.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def _run(*args: str, timeout: float) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", *args], cwd=REPO, capture_output=True, text=True, timeout=timeout)


def test_ruff_is_clean():
    res = _run("ruff", "check", "--no-fix", ".", timeout=120)
    assert res.returncode == 0, f"ruff check found problems:\n{res.stdout}\n{res.stderr}"


@pytest.mark.slow
def test_mypy_is_clean():
    res = _run("mypy", timeout=600)
    assert res.returncode == 0, f"mypy found problems:\n{res.stdout}\n{res.stderr}"
