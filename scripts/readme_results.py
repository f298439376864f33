"""Write (or check) the README's "Results at a glance" block: the glance of every shipped table rendered from
the published per-table outputs in ``results/published/small`` (:mod:`bench.glance`).

    .venv/bin/python scripts/readme_results.py           # rewrite the block between its markers in README.md
    .venv/bin/python scripts/readme_results.py --check   # exit 1 if the block differs from a fresh rendering

Run it after publishing a table (``bench report --out results/published --scale small``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from bench.data.atomic import atomic_write_text
from bench.glance import current_block, render_glance, replace_block
from bench.pipeline import load_tables

REPO = Path(__file__).resolve().parents[1]
PUBLISHED = "results/published/small"


def readme_block(repo: Path = REPO) -> str:
    """The block as it should read: every shipped table's glance, links relative to the README."""
    return render_glance(load_tables(["all"]), repo / PUBLISHED, link_prefix=f"{PUBLISHED}/")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--check", action="store_true", help="do not write; exit 1 when the block is out of date")
    args = ap.parse_args(argv)
    readme = REPO / "README.md"
    text = readme.read_text(encoding="utf-8")
    block = readme_block()
    if args.check:
        stale = current_block(text, readme) != block
        print("README results block is out of date: run scripts/readme_results.py" if stale else "README results block is current")
        return 1 if stale else 0
    atomic_write_text(readme, replace_block(text, block, readme))
    print(f"wrote the results block of {readme}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
