"""Tests' way to aggregate hand-written result rows: match them to a table by their labels, not by id.

The harness matches stored results to a table by planned job id (:func:`bench.aggregate.select_by_id`).
Tests that write result JSONs by hand (made-up job ids) match them as older versions of the harness did:
a job belongs to a table cell through its ``table`` and ``row`` fields (the row's label), its group (the
``group`` field if present, else its ``dataset``; when several groups share a dataset, the group whose
``overrides`` are all in the job's ``config``), and its ``scale``, ``scene`` and ``seed``, which must be
among those the spec resolves for that scale. When several results exist for one (row, group, scene,
seed), the most recently ``created`` wins and the others are counted as superseded.

Import it as ``from label_match import build_table_by_label`` (pytest puts this folder on ``sys.path``).
"""

from __future__ import annotations

from typing import Iterable

import pandas as pd

from bench.report import report_from_jobs
from bench.results_io import empty_results
from bench.table_report import TableReport
from bench.table_spec import DatasetGroup, TableSpec, resolve


def _match_group(jobs: pd.DataFrame, spec: TableSpec, g: DatasetGroup) -> pd.Series:
    explicit = jobs["group"].notna()
    by_group = explicit & (jobs["group"].astype(object) == g.id)
    sharing = [x for x in spec.groups if x.dataset == g.dataset]
    by_dataset = ~explicit & (jobs["dataset"] == g.dataset)
    if len(sharing) > 1:
        fits = jobs["config"].map(lambda c: all(k in c and c[k] == v for k, v in g.overrides.items()))
        by_dataset = by_dataset & fits.astype(bool)
    return by_group | by_dataset


def select_by_label(spec: TableSpec, df: pd.DataFrame, scale: str) -> tuple[pd.DataFrame, int, int]:
    """Jobs of ``spec`` at ``scale`` with a ``gid`` column; returns (jobs, n_unmatched, n_superseded).

    By the stored table / row labels (results written by this table only; the most recent per cell wins)."""
    mine = df[(df["table"] == spec.name) & (df["scale"] == scale)] if len(df) else df
    res = resolve(spec, scale)
    parts = []
    for g in spec.groups:
        sel = mine[_match_group(mine, spec, g)] if len(mine) else mine
        sel = sel[sel["scene"].isin(res.scenes[g.id]) & sel["seed"].isin(res.seeds)
                  & sel["row"].isin([r.label for r in spec.rows])]
        parts.append(sel.assign(gid=g.id))
    both = pd.concat(parts, ignore_index=True) if parts else mine.assign(gid="")
    matched_paths = set(both["path"])
    n_unmatched = int((~mine["path"].isin(matched_paths)).sum()) if len(mine) else 0
    both = both.sort_values("created", kind="stable")
    dedup = both.drop_duplicates(["row", "gid", "scene", "seed"], keep="last")
    return dedup.reset_index(drop=True), n_unmatched, len(both) - len(dedup)


def build_table_by_label(spec: TableSpec, df: pd.DataFrame, scale: str,
                         available_methods: Iterable[str] | None = None) -> TableReport:
    """:func:`bench.report.build_table` for hand-written results: matched by :func:`select_by_label`."""
    jobs, n_unmatched, n_superseded = select_by_label(spec, df if df is not None else empty_results(), scale)
    return report_from_jobs(spec, scale, jobs, available_methods, n_unmatched, n_superseded)
