"""The documented commands run: the code blocks of the README and of the manual's usage pages are read, and every
command that neither trains nor runs a table (``bench list``, ``bench config``, ``bench report``, ``bench scenes make``
/ ``card``) is run at the tiny scale in a temporary folder, in the order the pages give them; the commands that train (``run``, ``regress``, ``study``, ``fit``) are recognised and left to
the end-to-end tests of their own."""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
# Pages whose commands a user runs as written, grouped in the order a user runs them: the datasheet page cards the
# README's `data/s0`.
PAGES = (("README.md", "docs/datasheet.md"), ("docs/usage.md",))
CHEAP = ("list", "config", "report", "scenes")  # subcommands that do not train
TRAINING = ("run", "regress", "study", "fit")


def code_blocks(markdown: str) -> list[str]:
    """Fenced blocks and 4-space indented blocks (a blank or non-indented line ends one)."""
    blocks = re.findall(r"^```[^\n]*\n(.*?)^```", markdown, re.MULTILINE | re.DOTALL)
    text = re.sub(r"^```.*?^```", "", markdown, flags=re.MULTILINE | re.DOTALL)
    blocks += re.findall(r"(?:^\n)((?:^ {4}.*\n)+)", text, re.MULTILINE)
    return blocks


def bench_commands(markdown: str) -> list[list[str]]:
    """The ``bench`` commands of the README's code blocks as argument lists (after ``bench``): comments and
    ``[optional]`` parts dropped, continuation lines joined."""
    commands = []
    for block in code_blocks(markdown):
        for line in block.replace("\\\n", " ").splitlines():
            line = re.sub(r"\s#\s.*$", "", line.strip())
            m = re.search(r"(?:^|&& )(?:\.venv/bin/)?bench (.*)$", line)
            if m:
                commands.append(shlex.split(re.sub(r"\[[^\]]*\]", "", m.group(1))))
    return commands


def tiny(args: list[str], tmp: Path) -> list[str]:
    """The command at the tiny scale, writing into ``tmp`` (its relative ``--out`` lands there too)."""
    args = list(args)
    if args[0] in ("scenes", "report"):
        args = [a for i, a in enumerate(args) if a != "--scale" and (i == 0 or args[i - 1] != "--scale")] + ["--scale", "tiny"]
    if args[0] == "report" and "--out" not in args:
        args += ["--out", str(tmp / "results")]
    return args


def test_the_readme_names_every_command_it_documents():
    commands = bench_commands((REPO / "README.md").read_text(encoding="utf-8"))
    names = {" ".join(c[:2]) if c[0] in ("scenes", "study") else c[0] for c in commands}
    assert {"list", "config", "report", "scenes make", "scenes card", "run", "regress", "study convergence", "fit"} <= names
    assert all(c[0] in CHEAP + TRAINING for c in commands), commands


def test_the_extraction_reads_blocks_and_drops_options_and_comments():
    md = ("text\n\n    bench list        # what\n    .venv/bin/bench report [--table a b] --scale small\n\nmore\n\n"
          "```\nbash x.sh && .venv/bin/bench run --table ablation\nbench study convergence m s \\\n  --seeds 0\n```\n"
          "    not a block: no blank line before\n")
    assert bench_commands(md) == [["run", "--table", "ablation"], ["study", "convergence", "m", "s", "--seeds", "0"],
                                  ["list"], ["report", "--scale", "small"]]


def your_own_file(args: list[str]) -> bool:
    """True when the command names a file of the user's (a recipe YAML that is not in the repository)."""
    return any(a.endswith(".yaml") and not (REPO / a).exists() for a in args)


@pytest.mark.slow
def test_the_cheap_documented_commands_run_at_the_tiny_scale(tmp_path):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")]))}
    ran = []
    for n, group in enumerate(PAGES):  # each group's commands in order, in a folder of its own (later ones use earlier outputs)
        cwd = tmp_path / str(n)
        cwd.mkdir()
        for page, args in [(page, c) for page in group for c in bench_commands((REPO / page).read_text(encoding="utf-8"))]:
            if args[0] not in CHEAP or your_own_file(args):
                continue
            args = tiny(args, cwd)
            res = subprocess.run([sys.executable, "-m", "bench.cli", *args], cwd=cwd, env=env, capture_output=True,
                                 text=True, timeout=600)
            assert res.returncode == 0, f"{page}: bench {' '.join(args)} failed:\n{res.stdout[-2000:]}\n{res.stderr[-2000:]}"
            assert res.stdout.strip(), f"{page}: bench {' '.join(args)} printed nothing"
            ran.append((page, args[0]))
    assert {page for page, _ in ran} == {page for group in PAGES for page in group} and len(ran) >= 8
    assert (tmp_path / "0" / "data" / "s0").is_dir()  # the README's `bench scenes make ... --out data/s0`
