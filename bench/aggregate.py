"""Result rows -> the cells of one table: which stored results count for it, and their statistics.

Matching (:func:`select_by_id`): a result counts for a table when its ``base_id`` (its job id without the
torch thread count) is one of the table's planned jobs (:func:`bench.runner.plan_index`); it is labelled
with the plan's row and group, so a job another table ran (same method, config, scene, variant, seed,
scale, protocol) counts here too. When several results share a base id, the most recently ``created``
wins and the others are counted as superseded; results of this table with other ids (older configs or
code versions) are counted as unmatched.

Statistics of a cell (row x group x metric), computed over the successful jobs:

* ``mean``: mean over all (scene, seed) values;
* ``std``: sample standard deviation (ddof=1) across seeds of the per-seed mean over scenes, i.e. the
  seed-to-seed spread of the table entry (NaN with a single seed, shown without ``±``);
* ``n``: number of values, ``n_expected`` = scenes x seeds, ``n_failed``, ``n_pending`` (no result yet).

A cell with fewer than ``n_expected`` values keeps those counts, and the markdown marks it
(:func:`bench.table_markdown.format_cell`), so a partly failed row is never silently averaged over
fewer jobs.

Convergence: a spec with ``convergence`` judges every trained row (:func:`judge_rows`,
:mod:`bench.convergence`); the tidy CSV has the verdict in ``converged`` (empty at a smoke-test scale,
:mod:`bench.scales`).

Also per table: the stage timings (:func:`timing_frame`) and the accuracy along the schedule
(:func:`curve_table`).
"""

from __future__ import annotations

import math
from typing import Any, Mapping, Sequence

import numpy as np
import pandas as pd

from bench.convergence import RowConvergence, judge_row
from bench.scales import is_smoke
from bench.table_report import Cell, TableReport
from bench.table_spec import TableSpec, resolve

TIDY_COLUMNS = [
    "table", "row", "group", "dataset", "metric", "source", "mean", "std", "n", "n_expected",
    "n_failed", "n_pending", "unit", "status", "converged",
]
TIME_COLUMNS = ["table", "row", "group", "quantity", "unit", "mean", "std", "n"]
CURVE_COLUMNS = ["table", "row", "group", "fraction", "iterations", "seconds", "metric", "mean", "std", "n"]
PlanIndex = Mapping[str, Sequence[Any]]  # job id -> the table's JobPlans with that id (bench.runner.plan_index)


def select_by_id(spec: TableSpec, df: pd.DataFrame, scale: str, plans: PlanIndex) -> tuple[pd.DataFrame, int, int]:
    """The results whose job id is one of the table's planned jobs, labelled with the plan's row and
    group: a job another table ran (same method, config, scene, variant, seed, scale, protocol) counts
    here too. Results of this table with other ids (older configs or code versions) are unmatched."""
    records = []
    n_superseded = 0
    if len(df):
        matched = df[df["base_id"].isin(list(plans))]
        # the same job run with another torch thread count (another job id, same base id): the newest counts
        newest = matched.sort_values("created").drop_duplicates("base_id", keep="last")
        n_superseded = len(matched) - len(newest)
        for rec in newest.to_dict("records"):
            for plan in plans[rec["base_id"]]:
                records.append({**rec, "table": spec.name, "row": plan.row, "group": plan.group, "gid": plan.group})
    both = pd.DataFrame.from_records(records, columns=list(df.columns) + ["gid"]) if records else df.iloc[:0].assign(gid="")
    mine = df[(df["table"] == spec.name) & (df["scale"] == scale)] if len(df) else df
    n_unmatched = int((~mine["base_id"].isin(list(plans))).sum()) if len(mine) else 0
    return both.reset_index(drop=True), n_unmatched, n_superseded


def _values(ok: pd.DataFrame, key: str) -> pd.DataFrame:
    vals = ok["metrics"].map(lambda m: m.get(key))
    vals = pd.to_numeric(vals, errors="coerce").astype(float)
    return pd.DataFrame({"seed": ok["seed"].to_numpy(), "v": vals.to_numpy()})


def _cell(jobs: pd.DataFrame, key: str, n_expected: int, implemented: bool) -> Cell:
    ok = jobs[jobs["status"] == "ok"]
    n_failed = int((jobs["status"] == "failed").sum())
    n_pending = n_expected - len(jobs)
    if len(ok) == 0:
        status = "failed" if n_failed else ("pending" if implemented else "not_implemented")
        return Cell(math.nan, math.nan, 0, n_expected, n_failed, n_pending, 0, status)
    v = _values(ok, key)
    v = v[np.isfinite(v["v"])]
    if len(v) == 0:
        return Cell(math.nan, math.nan, 0, n_expected, n_failed, n_pending, 0, "not_reported")
    per_seed = v.groupby("seed")["v"].mean()
    std = float(per_seed.std(ddof=1)) if len(per_seed) > 1 else math.nan
    status = "complete" if len(v) == n_expected else "partial"
    return Cell(float(v["v"].mean()), std, len(v), n_expected, n_failed, n_pending, len(per_seed), status)


def table_cells(spec: TableSpec, jobs: pd.DataFrame, scale: str, unavailable: set[str]) -> dict[tuple[str, str, str], Cell]:
    """Every cell of ``spec`` at ``scale`` (row x group x measured column or extra metric) over the
    matched ``jobs`` (with their ``gid``); a row whose method is in ``unavailable`` and has no results
    is "not_implemented" rather than "pending"."""
    res = resolve(spec, scale)
    cells: dict[tuple[str, str, str], Cell] = {}
    for r in spec.rows:
        for g in spec.groups:
            sub = jobs[(jobs["row"] == r.label) & (jobs["gid"] == g.id)]
            for key in [c.key for c in g.columns if not c.paper_only] + list(g.extra_metrics):
                cells[(r.label, g.id, key)] = _cell(sub, key, res.n_expected(g.id), r.method not in unavailable)
    return cells


def timing_frame(spec: TableSpec, jobs: pd.DataFrame) -> pd.DataFrame:
    """The ``<table>_time.csv`` frame (:data:`TIME_COLUMNS`): per row x group, the mean / sample std /
    count of every stage's wall seconds and of the iterations over the successful jobs."""
    rows: list[dict[str, Any]] = []
    ok = jobs[jobs["status"] == "ok"]
    for label, gid in [(r.label, g.id) for r in spec.rows for g in spec.groups]:
        sub = ok[(ok["row"] == label) & (ok["gid"] == gid)]
        if sub.empty:
            continue
        stages = list(dict.fromkeys(k for t in sub["timings"] for k in t))
        for stage in stages:
            s = pd.to_numeric(sub["timings"].map(lambda t: t.get(stage)), errors="coerce").dropna()
            rows.append({"table": spec.name, "row": label, "group": gid, "quantity": stage, "unit": "s",
                         "mean": s.mean(), "std": s.std(ddof=1) if len(s) > 1 else math.nan, "n": len(s)})
        it = pd.to_numeric(sub["iterations"], errors="coerce").dropna()
        if len(it):
            rows.append({"table": spec.name, "row": label, "group": gid, "quantity": "iterations", "unit": "",
                         "mean": it.mean(), "std": it.std(ddof=1) if len(it) > 1 else math.nan, "n": len(it)})
    return pd.DataFrame(rows, columns=TIME_COLUMNS)


def tidy_frame(spec: TableSpec, cells: dict[tuple[str, str, str], Cell],
               convergence: Mapping[tuple[str, str], RowConvergence]) -> pd.DataFrame:
    """The ``<table>.csv`` frame (:data:`TIDY_COLUMNS`): one line per cell (``source`` "ours", with its
    convergence verdict) and one per published value of the paper (``source`` "paper", in its unit)."""
    out: list[dict[str, Any]] = []
    units = {(g.id, c.key): c.unit for g in spec.groups for c in g.columns}
    paper_units = {(g.id, c.key): c.published_unit for g in spec.groups for c in g.columns}
    dataset = {g.id: g.dataset for g in spec.groups}
    for (label, gid, key), c in cells.items():
        out.append({"table": spec.name, "row": label, "group": gid, "dataset": dataset[gid], "metric": key,
                    "source": "ours", "mean": c.mean, "std": c.std, "n": c.n, "n_expected": c.n_expected,
                    "n_failed": c.n_failed, "n_pending": c.n_pending, "unit": units.get((gid, key), ""),
                    "status": c.status, "converged": _converged_value(convergence.get((label, gid)))})
    for r in spec.rows + spec.paper_only_rows:
        for gid, vals in (r.paper or {}).items():
            for key, v in vals.items():
                out.append({"table": spec.name, "row": r.label, "group": gid, "dataset": dataset[gid],
                            "metric": key, "source": "paper", "mean": math.nan if v is None else v,
                            "std": math.nan, "n": None, "n_expected": None, "n_failed": None,
                            "n_pending": None, "unit": paper_units[(gid, key)],
                            "status": "published" if v is not None else "not published", "converged": None})
    tidy = pd.DataFrame(out, columns=TIDY_COLUMNS)
    return tidy.astype({k: "Int64" for k in ("n", "n_expected", "n_failed", "n_pending")})


def _converged_value(v: RowConvergence | None) -> bool | None:
    return None if v is None or not v.judged else v.converged


def judge_rows(spec: TableSpec, jobs: pd.DataFrame, scale: str) -> dict[tuple[str, str], RowConvergence]:
    """(row label, group id) -> the row's convergence verdict (:func:`bench.convergence.judge_row`) over
    its successful jobs; empty when the spec has no ``convergence``; no verdict (``smoke``) at a
    smoke-test scale (:mod:`bench.scales`)."""
    if spec.convergence is None:
        return {}
    if is_smoke(scale):
        return {(r.label, g.id): RowConvergence(spec.convergence, 0, 0, 0, math.nan, smoke=True)
                for r in spec.rows for g in spec.groups}
    ok = jobs[jobs["status"] == "ok"]
    return {(r.label, g.id): judge_row(ok[(ok["row"] == r.label) & (ok["gid"] == g.id)][["seed", "curve", "config"]]
                                       .itertuples(index=False, name=None), spec.convergence)
            for r in spec.rows for g in spec.groups}


def curve_table(report: TableReport) -> pd.DataFrame:
    """Accuracy along the schedule, tidy: one line per (row, group, snapshot fraction, metric column)
    with the mean iterations and mean wall seconds of that snapshot (setup + training so far + its mesh
    extraction) and the metric's mean / sample std (ddof=1) / count over the scene x seed jobs that
    evaluated it (an early snapshot without metrics, e.g. an empty mesh, is left out). Columns:
    :data:`CURVE_COLUMNS`. The ``<table>_curve.csv`` output and the plot both come from this."""
    lines = []
    ok = report.jobs[report.jobs["status"] == "ok"] if len(report.jobs) else report.jobs
    for g in report.spec.groups:
        keys = [c.key for c in g.columns if not c.paper_only]
        sub_g = ok[ok["gid"] == g.id] if len(ok) else ok
        for label, sub in (sub_g.groupby("row", sort=False) if len(sub_g) else []):
            pts = [{"fraction": p.get("fraction"), "iterations": p.get("iterations"), "seconds": p.get("seconds"),
                    **{k: (p.get("metrics") or {}).get(k) for k in keys}}
                   for curve in sub["curve"] for p in curve if isinstance(p, dict) and isinstance(p.get("metrics") or {}, dict)]
            if not pts:
                continue
            cdf = pd.DataFrame(pts).apply(pd.to_numeric, errors="coerce").dropna(subset=["fraction", "seconds"])
            for frac, at in cdf.groupby("fraction", sort=True):
                for k in keys:
                    v = at[k].dropna()
                    if not len(v):
                        continue
                    lines.append({"table": report.spec.name, "row": str(label), "group": g.id, "fraction": float(frac),
                                  "iterations": float(at["iterations"].mean()), "seconds": float(at["seconds"].mean()),
                                  "metric": k, "mean": float(v.mean()), "std": float(v.std(ddof=1)) if len(v) > 1 else float("nan"),
                                  "n": int(len(v))})
    return pd.DataFrame(lines, columns=CURVE_COLUMNS)
