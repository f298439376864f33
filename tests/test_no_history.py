"""The product carries no development history: no numbered work session or tracker issue in any tracked
text file (README, docs, code, comments, docstrings, configs, test names), and no figure named by one.

A reader who was not there cannot use "as session N measured" or "by issue N's criteria" (N a number); a comment that
explains why a value is what it is names the study in ``docs/studies/`` or the measurement instead.
What the check matches: the word ``session`` or ``issue`` (any case, optionally plural) followed by a number,
with spaces, ``#``, ``-`` or ``_`` between ("Session N's", "issue #N", "session-N", "test_issueN", with N a number).
"""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

HISTORY = re.compile(r"(?<![a-z])(?:session|issue)s?[\s#_-]*\d", re.IGNORECASE)
# A figure or any other file in docs/ named like ``s6_<what>.png`` (the number of the session that made it first).
SESSION_NAMED_FILE = re.compile(r"^s\d+_")


def tracked_files(root: Path) -> list[Path]:
    """Files git tracks under ``root`` (every file but ``.git`` / ``.venv`` / caches when git is unavailable)."""
    try:
        out = subprocess.run(["git", "ls-files", "-z"], cwd=root, capture_output=True, check=True, timeout=60).stdout
        return [root / p for p in out.decode().split("\0") if p]
    except (OSError, subprocess.CalledProcessError):
        skip = {".git", ".venv", "__pycache__", ".mypy_cache", ".ruff_cache", ".pytest_cache"}
        return [p for p in root.rglob("*") if p.is_file() and not skip.intersection(p.relative_to(root).parts)]


def history_mentions(root: Path, files: list[Path]) -> list[str]:
    """``path:line: text`` for every numbered session / issue in the text files among ``files`` (binary skipped)."""
    hits = []
    for path in files:
        try:
            text = path.read_text(encoding="utf-8")
        except (UnicodeDecodeError, FileNotFoundError, IsADirectoryError):
            continue
        for number, line in enumerate(text.splitlines(), start=1):
            if HISTORY.search(line):
                hits.append(f"{path.relative_to(root)}:{number}: {line.strip()[:160]}")
    return hits


def session_named_docs(root: Path, files: list[Path]) -> list[str]:
    """Files under ``docs/`` whose name starts with a session number (``s6_...``)."""
    return [str(p.relative_to(root)) for p in files
            if p.relative_to(root).parts[:1] == ("docs",) and SESSION_NAMED_FILE.match(p.name)]


def test_no_numbered_session_or_issue_in_the_tree():
    hits = history_mentions(REPO, tracked_files(REPO))
    assert not hits, "development history in the product (name the study or the measurement instead):\n" + "\n".join(hits)


def test_no_figure_named_by_a_session():
    assert session_named_docs(REPO, tracked_files(REPO)) == []


def test_the_check_fails_on_a_planted_mention(tmp_path):
    docs = tmp_path / "docs"
    docs.mkdir()
    word = "ses" + "sion"  # spelt apart so this file itself stays clean
    planted = docs / "guide.md"
    planted.write_text(f"# Guide\n\nThe budget was fixed in {word} 12.\n")
    variants = docs / "variants.md"
    variants.write_text(f"As {word.capitalize()} 10's run showed.\nBy iss{'ue'} #14's criteria.\n{word}-24 run.\n")
    clean = docs / "clean.md"
    clean.write_text(f"Datasets are cached per {word}; a fixture of {word} scope. An iss{'ue'} with 2 files.\n")
    figure = docs / f"s{6}_missing_objects.png"  # a figure named by the session that made it
    figure.write_bytes(b"\x89PNG\r\n\x1a\n\x00\x00")
    files = [planted, variants, clean, figure]

    hits = history_mentions(tmp_path, files)

    assert [h.split(": ", 1)[0] for h in hits] == [
        "docs/guide.md:3", "docs/variants.md:1", "docs/variants.md:2", "docs/variants.md:3"]
    assert session_named_docs(tmp_path, files) == [f"docs/{figure.name}"]
