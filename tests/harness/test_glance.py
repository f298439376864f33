"""The README's "Results at a glance" block (:mod:`bench.glance`): it equals a fresh rendering of the published
tables, and the rendering reads the published outputs (tidy CSV, claims of the markdown), so it follows them."""

from __future__ import annotations

import shutil
from pathlib import Path

import pandas as pd
import pytest

from bench.data.errors import BenchInputError
from bench.glance import BEGIN, END, current_block, render_glance, replace_block, table_glance
from bench.pipeline import load_tables
from bench.table_markdown import read_claims

REPO = Path(__file__).resolve().parents[2]
PUBLISHED = REPO / "results" / "published" / "small"


@pytest.fixture(scope="module")
def readme_results(load_script):
    return load_script("readme_results")


def test_the_readme_block_equals_a_fresh_rendering(readme_results):
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    assert current_block(readme) == readme_results.readme_block(), "run scripts/readme_results.py"
    assert readme_results.main(["--check"]) == 0


def test_every_published_table_appears_in_paper_order_with_its_claims():
    block = render_glance(load_tables(["all"]), PUBLISHED)
    starts = [block.index(f"**Table {n}:") for n in (1, 2, 3, 4, 5)]
    assert starts == sorted(starts)
    for spec in load_tables(["all"]):
        claims = read_claims((PUBLISHED / f"{spec.name}.md").read_text(encoding="utf-8"))
        assert [c.id for c in claims] == [c.id for c in spec.claims]  # every claim of the spec, read back in order
        assert all(c.verdict.split(" (")[0] in ("HELD", "NOT HELD", "UNDECIDED") for c in claims)
        assert all(f"(`{c.id}`)" in block for c in claims)


def test_the_glance_follows_the_published_files(tmp_path):
    [spec] = load_tables(["llff"])
    shutil.copy(PUBLISHED / "llff.md", tmp_path / "llff.md")
    tidy = pd.read_csv(PUBLISHED / "llff.csv")
    ours_psnr = (tidy["row"] == "3DGS") & (tidy["metric"] == "psnr") & (tidy["source"] == "ours")
    tidy.loc[ours_psnr, ["mean", "std", "n", "n_failed"]] = [12.5, 0.75, 4, 2]
    tidy.to_csv(tmp_path / "llff.csv", index=False)

    glance = table_glance(spec, tmp_path, link_prefix="pub/")

    assert "| 3DGS | 12.50 ± 0.75 (4/6, 2 failed) / 15.52 | - |" in glance
    assert "([llff.md](pub/llff.md))" in glance and "PSNR [dB], higher is better" in glance
    assert "- UNDECIDED (within the seed spread; as measured: NOT HELD): MonoInstance on FSGS improves PSNR" in glance


def test_a_missing_output_or_missing_markers_is_one_clear_error(tmp_path):
    [spec] = load_tables(["llff"])
    with pytest.raises(BenchInputError, match="llff.csv.*run `bench report` first"):
        table_glance(spec, tmp_path)
    with pytest.raises(BenchInputError, match="no generated block"):
        replace_block("# A README without the block\n", "x\n")
    doc = f"intro\n{BEGIN}\nold\n{END}\nrest\n"
    assert replace_block(doc, "new\n") == f"intro\n{BEGIN}\nnew\n{END}\nrest\n"
    assert current_block(replace_block(doc, "new\n")) == "new\n"


def test_claim_lines_read_back_from_a_fresh_rendering():
    from bench.aggregate import select_by_id
    from bench.report import report_from_jobs
    from bench.results_io import empty_results
    from bench.table_markdown import to_markdown

    for spec in load_tables(["ablation", "llff"]):
        jobs, _, _ = select_by_id(spec, empty_results(), "tiny", {})
        report = report_from_jobs(spec, "tiny", jobs)
        claims = read_claims(to_markdown(report))
        assert [(c.id, c.verdict) for c in claims] == [(r.claim.id, r.verdict) for r in report.claims]
        assert [c.paper_verdict for c in claims] == [r.paper_verdict for r in report.claims]
