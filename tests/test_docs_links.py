"""The manual holds together: every relative link in the README, the changelog and ``docs/`` resolves (the file
exists and, for a ``#fragment`` into a markdown file, the heading exists), and the indexes list every document
(``docs/README.md`` every page of ``docs/``, ``docs/studies/README.md`` every study)."""

from __future__ import annotations

import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DOCS = REPO / "docs"

LINK = re.compile(r"(?<!\!)\[[^\]]*\]\(([^)\s]+)\)|!\[[^\]]*\]\(([^)\s]+)\)")
FENCE = re.compile(r"^```.*?^```", re.MULTILINE | re.DOTALL)


def documents(root: Path = REPO) -> list[Path]:
    """The markdown the manual consists of: README.md, CHANGELOG.md and every ``docs/**/*.md``."""
    return [root / "README.md", root / "CHANGELOG.md", *sorted((root / "docs").rglob("*.md"))]


def slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, markup and punctuation dropped, spaces to hyphens."""
    text = re.sub(r"[`*]|\[([^\]]*)\]\([^)]*\)", lambda m: m.group(1) or "", heading.strip().lower())
    return re.sub(r"[^\w\- ]", "", text).replace(" ", "-")


def anchors(path: Path) -> set[str]:
    text = FENCE.sub("", path.read_text(encoding="utf-8"))
    return {slug(m.group(1)) for m in re.finditer(r"^#{1,6} (.+)$", text, re.MULTILINE)}


def links(path: Path) -> list[str]:
    """Relative link targets in a markdown file (outside code blocks; web links and mail left out)."""
    text = FENCE.sub("", path.read_text(encoding="utf-8"))
    targets = [a or b for a, b in LINK.findall(text)]
    return [t for t in targets if not re.match(r"^[a-z]+:", t)]


def broken_links(path: Path) -> list[str]:
    """``target: why`` for every relative link of ``path`` that does not resolve."""
    bad = []
    for target in links(path):
        file, _, fragment = target.partition("#")
        dest = (path.parent / file).resolve() if file else path
        if not dest.exists():
            bad.append(f"{target}: no such file")
        elif fragment and dest.suffix == ".md" and fragment not in anchors(dest):
            bad.append(f"{target}: no heading #{fragment} in {dest.relative_to(REPO)}")
    return bad


def test_every_relative_link_resolves():
    bad = {str(p.relative_to(REPO)): b for p in documents() if (b := broken_links(p))}
    assert not bad, f"broken links: {bad}"


def test_docs_index_lists_every_page_and_the_studies_index_every_study():
    def linked(index: Path) -> set[Path]:
        return {(index.parent / t.partition("#")[0]).resolve() for t in links(index) if t.partition("#")[0]}

    pages = {p.resolve() for p in DOCS.glob("*.md") if p.name != "README.md"} | {(DOCS / "studies" / "README.md").resolve()}
    studies = {p.resolve() for p in (DOCS / "studies").glob("*.md") if p.name != "README.md"}
    assert pages - linked(DOCS / "README.md") == set()
    assert studies - linked(DOCS / "studies" / "README.md") == set()


def test_a_broken_link_and_a_missing_heading_are_found(tmp_path, monkeypatch):
    monkeypatch.setattr(__import__(__name__), "REPO", tmp_path)
    (tmp_path / "a.md").write_text("# Title `code` (x)\n\n## Second: part\n")
    doc = tmp_path / "b.md"
    doc.write_text("[ok](a.md#title-code-x) [ok2](a.md#second-part) ![fig](a.md) [web](https://x.org/y)\n"
                   "[gone](missing.md) [nohead](a.md#third)\n```\n[in code](nowhere.md)\n```\n")
    assert broken_links(doc) == ["missing.md: no such file", "a.md#third: no heading #third in a.md"]
