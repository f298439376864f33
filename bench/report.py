"""Result rows -> tables: aggregation, CSV, markdown, accuracy-vs-time plots and the claims check.

Input: one JSON per job in ``<results_dir>/jobs/`` (written by the runner). A job belongs to a table
cell through its ``table`` and ``row`` fields (the row's label), its group (the ``group`` field if
present, else its ``dataset``; when several groups share a dataset, the group whose ``overrides`` are
all in the job's ``config``), and its ``scale``, ``scene`` and ``seed``, which must be among those the
spec resolves for that scale. When several results exist for one (row, group, scene, seed), the most
recently ``created`` wins and the others are counted as superseded.

Statistics of a cell (row x group x metric), computed over the successful jobs:

* ``mean``: mean over all (scene, seed) values;
* ``std``: sample standard deviation (ddof=1) across seeds of the per-seed mean over scenes, i.e. the
  seed-to-seed spread of the table entry (NaN with a single seed, shown without ``±``);
* ``n``: number of values, ``n_expected`` = scenes x seeds, ``n_failed``, ``n_pending`` (no result yet).

A cell with fewer than ``n_expected`` values is marked, e.g. ``0.741 ± 0.010 (2/3, 1 failed)``, so a
partly failed row is never silently averaged over fewer jobs.

Claims: a claim compares means. For each comparison we also say whether the difference exceeds the
combined spread ``std_a + std_b`` (a deliberately conservative test; unknown with one seed).

Convergence: a spec with ``convergence`` judges every trained row (:mod:`bench.convergence`); the table
shows the verdict per row, the tidy CSV has it in ``converged``, and a claim comparing a row that has not
converged is ``UNDECIDED (not converged: ...)``: a row that has not converged is not a result.
"""

from __future__ import annotations

import io
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

import numpy as np
import pandas as pd

from bench.data.atomic import atomic_write_many, atomic_write_text
from bench.convergence import RowConvergence, judge_row
from bench.data.errors import BenchInputError
from bench.jobs import REQUIRED_FIELDS, RESULT_SCHEMA
from bench.tables import ClaimSpec, DatasetGroup, TableSpec, resolve

RESULT_COLUMNS = [
    "job_id", "base_id", "table", "row", "method", "group", "dataset", "scene", "seed", "scale", "status",
    "error_type", "error_message", "metrics", "timings", "iterations", "curve", "config", "created",
    "worker", "versions", "path",
]
TIDY_COLUMNS = [
    "table", "row", "group", "dataset", "metric", "source", "mean", "std", "n", "n_expected",
    "n_failed", "n_pending", "unit", "status", "converged",
]
TIME_COLUMNS = ["table", "row", "group", "quantity", "unit", "mean", "std", "n"]
NOT_IMPLEMENTED = "pending (method not implemented yet)"


# --------------------------------------------------------------------------------------------------
# reading results


def _read_job(path: Path) -> dict[str, Any]:
    try:
        d = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise BenchInputError(path, f"corrupt result JSON: {e}") from None
    if not isinstance(d, dict):
        raise BenchInputError(path, f"expected a JSON object, got {type(d).__name__}")
    missing = [k for k in REQUIRED_FIELDS if k not in d]
    if missing:
        raise BenchInputError(path, f"missing key(s) {missing}")
    if d.get("schema", RESULT_SCHEMA) != RESULT_SCHEMA:
        raise BenchInputError(path, f"schema {d.get('schema')!r} is not supported (expected {RESULT_SCHEMA})")
    if d["status"] not in ("ok", "failed"):
        raise BenchInputError(path, f"status: {d['status']!r} is not 'ok' or 'failed'")
    for key in ("metrics", "timings", "config"):
        if not isinstance(d.get(key) or {}, dict):
            raise BenchInputError(path, f"{key}: expected an object")
    if not isinstance(d.get("curve") or [], list):
        raise BenchInputError(path, "curve: expected a list")
    err = d.get("error") or {}
    try:
        seed = int(d["seed"])
    except (TypeError, ValueError):
        raise BenchInputError(path, f"seed: expected an integer, got {d['seed']!r}") from None
    return {
        "job_id": str(d["job_id"]), "base_id": str(d.get("base_id") or d["job_id"]), "table": str(d["table"]), "row": str(d["row"]),
        "method": str(d["method"]), "group": d.get("group"), "dataset": str(d["dataset"]),
        "scene": str(d["scene"]), "seed": seed, "scale": str(d["scale"]),
        "status": d["status"],
        "error_type": err.get("type") if isinstance(err, dict) else None,
        "error_message": err.get("message") if isinstance(err, dict) else str(err),
        "metrics": dict(d.get("metrics") or {}), "timings": dict(d.get("timings") or {}),
        "iterations": d.get("iterations"), "curve": list(d.get("curve") or []),
        "config": dict(d.get("config") or {}), "created": str(d.get("created") or ""),
        "worker": d.get("worker"), "versions": dict(d.get("versions") or {}), "path": str(path),
    }


def collect_results(results_dir: str | Path) -> pd.DataFrame:
    """One row per job JSON in ``<results_dir>/jobs/`` (columns :data:`RESULT_COLUMNS`).

    ``metrics``, ``timings``, ``config`` (dicts) and ``curve`` (list) stay Python objects. Hidden
    files (the atomic writer's temporaries) are skipped. A missing ``jobs/`` folder gives an empty
    frame; a corrupt or incomplete JSON raises :class:`BenchInputError` naming the file.
    """
    jobs = Path(results_dir) / "jobs"
    records = [_read_job(p) for p in sorted(jobs.glob("*.json")) if not p.name.startswith(".")] if jobs.is_dir() else []
    return pd.DataFrame.from_records(records, columns=RESULT_COLUMNS) if records else empty_results()


def empty_results() -> pd.DataFrame:
    """An empty results frame with the columns :func:`collect_results` returns."""
    return pd.DataFrame(columns=RESULT_COLUMNS)


# --------------------------------------------------------------------------------------------------
# aggregation


@dataclass(frozen=True)
class Cell:
    """Aggregate of one row x group x metric over seeds and scenes (see the module docstring)."""

    mean: float
    std: float
    n: int
    n_expected: int
    n_failed: int
    n_pending: int
    n_seeds: int
    status: str  # "complete" | "partial" | "failed" | "pending" | "not_implemented" | "not_reported"

    @property
    def has_value(self) -> bool:
        return self.n > 0 and math.isfinite(self.mean)


@dataclass
class ClaimResult:
    """Outcome of one claim: ``verdict`` is "HELD", "NOT HELD" or "UNDECIDED (...)"."""

    claim: ClaimSpec
    verdict: str
    details: list[str] = field(default_factory=list)
    paper_verdict: str = "n/a"
    partial: bool = False


@dataclass
class TableReport:
    """Everything rendered for one table at one scale."""

    spec: TableSpec
    scale: str
    cells: dict[tuple[str, str, str], Cell]  # (row label, group id, metric) -> Cell
    jobs: pd.DataFrame  # the matched, de-duplicated jobs of this table (ok and failed)
    tidy: pd.DataFrame  # TIDY_COLUMNS
    timing: pd.DataFrame  # TIME_COLUMNS
    claims: list[ClaimResult]
    unavailable: set[str]
    n_unmatched: int = 0
    n_superseded: int = 0
    convergence: dict[tuple[str, str], RowConvergence] = field(default_factory=dict)  # (row, group) -> verdict; empty without a spec

    def not_converged(self, label: str, gid: str) -> bool:
        """True if the row was judged in this group and has not converged."""
        v = self.convergence.get((label, gid))
        return v is not None and v.judged and not v.converged


def _match_group(jobs: pd.DataFrame, spec: TableSpec, g: DatasetGroup) -> pd.Series:
    explicit = jobs["group"].notna()
    by_group = explicit & (jobs["group"].astype(object) == g.id)
    sharing = [x for x in spec.groups if x.dataset == g.dataset]
    by_dataset = ~explicit & (jobs["dataset"] == g.dataset)
    if len(sharing) > 1:
        fits = jobs["config"].map(lambda c: all(k in c and c[k] == v for k, v in g.overrides.items()))
        by_dataset = by_dataset & fits.astype(bool)
    return by_group | by_dataset


PlanIndex = Mapping[str, Sequence[Any]]  # job id -> the table's JobPlans with that id (bench.runner.plan_index)


def _select_by_id(spec: TableSpec, df: pd.DataFrame, scale: str, plans: PlanIndex) -> tuple[pd.DataFrame, int, int]:
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


def _select(spec: TableSpec, df: pd.DataFrame, scale: str, plans: PlanIndex | None = None) -> tuple[pd.DataFrame, int, int]:
    """Jobs of ``spec`` at ``scale`` with a ``gid`` column; returns (jobs, n_unmatched, n_superseded).

    With ``plans`` (the table's job ids), by job id (:func:`_select_by_id`); without, by the stored
    table / row labels (results written by this table only; the most recent per cell wins)."""
    if plans is not None:
        return _select_by_id(spec, df, scale, plans)
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


def format_cell(cell: Cell, fmt: str) -> str:
    """Text of one cell: ``mean ± std`` with a marker when jobs are missing, failed or pending."""
    if cell.status == "not_implemented":
        return NOT_IMPLEMENTED
    if cell.status == "pending":
        return "pending"
    if cell.status == "failed":
        pend = f", {cell.n_pending} pending" if cell.n_pending else ""
        return f"failed ({cell.n_failed}/{cell.n_expected} failed{pend})"
    if cell.status == "not_reported":
        return "n/a (not reported)"
    text = format(cell.mean, fmt)
    if math.isfinite(cell.std):
        text += f" ± {format(cell.std, fmt)}"
    if cell.n < cell.n_expected:
        extra = [f"{cell.n}/{cell.n_expected}"]
        if cell.n_failed:
            extra.append(f"{cell.n_failed} failed")
        if cell.n_pending:
            extra.append(f"{cell.n_pending} pending")
        missing = cell.n_expected - cell.n - cell.n_failed - cell.n_pending
        if missing:
            extra.append(f"{missing} not reported")
        text += f" ({', '.join(extra)})"
    return text


def _timing(spec: TableSpec, jobs: pd.DataFrame) -> pd.DataFrame:
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


def _tidy(spec: TableSpec, cells: dict[tuple[str, str, str], Cell],
          convergence: Mapping[tuple[str, str], RowConvergence]) -> pd.DataFrame:
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


def _judge_rows(spec: TableSpec, jobs: pd.DataFrame) -> dict[tuple[str, str], RowConvergence]:
    if spec.convergence is None:
        return {}
    ok = jobs[jobs["status"] == "ok"]
    return {(r.label, g.id): judge_row(ok[(ok["row"] == r.label) & (ok["gid"] == g.id)][["seed", "curve", "config"]]
                                       .itertuples(index=False, name=None), spec.convergence)
            for r in spec.rows for g in spec.groups}


def build_table(spec: TableSpec, df: pd.DataFrame, scale: str,
                available_methods: Iterable[str] | None = None, plans: PlanIndex | None = None) -> TableReport:
    """Aggregate the jobs of ``spec`` at ``scale`` into cells, timings and claim verdicts.

    ``available_methods``: names in the method registry; rows whose method is not among them (and
    which have no results) read "pending (method not implemented yet)". None means all are available.
    ``plans``: the table's job ids (:func:`bench.runner.plan_index`): results are matched by id, so
    jobs shared with other tables count; None matches by the stored table / row labels.
    """
    res = resolve(spec, scale)
    jobs, n_unmatched, n_superseded = _select(spec, df if df is not None else empty_results(), scale, plans)
    avail = None if available_methods is None else set(available_methods)
    unavailable = {r.method for r in spec.rows if avail is not None and r.method not in avail}  # type: ignore[misc]
    cells: dict[tuple[str, str, str], Cell] = {}
    for r in spec.rows:
        for g in spec.groups:
            sub = jobs[(jobs["row"] == r.label) & (jobs["gid"] == g.id)]
            for key in [c.key for c in g.columns if not c.paper_only] + list(g.extra_metrics):
                cells[(r.label, g.id, key)] = _cell(sub, key, res.n_expected(g.id), r.method not in unavailable)
    convergence = _judge_rows(spec, jobs)
    report = TableReport(spec, scale, cells, jobs, _tidy(spec, cells, convergence), _timing(spec, jobs), [], unavailable,
                         n_unmatched, n_superseded, convergence)
    report.claims = [check_claim(report, c) for c in spec.claims]
    return report


# --------------------------------------------------------------------------------------------------
# claims


def _fmt(x: float) -> str:
    return "n/a" if not math.isfinite(x) else f"{x:.4g}"


def _compare(a: float, b: float, better: str, strict: bool) -> bool:
    """True if ``a`` is better than ``b`` ("higher": a > b, "lower": a < b); non-strict allows ties."""
    d = a - b if better == "higher" else b - a
    tie = abs(d) <= 1e-9 * max(1.0, abs(a), abs(b))  # float noise is a tie, not a difference
    return (d > 0 and not tie) if strict else (d >= 0 or tie)


def _pairs(spec: TableSpec, claim: ClaimSpec) -> list[tuple[str, str, str, str, str, str, bool]]:
    """(group, row_a, metric_a, row_b, metric_b, better, strict): "a is `better` than b" comparisons."""
    out = []
    for gid in claim.groups:
        if claim.kind == "monotone":
            better = "higher" if claim.direction == "increasing" else "lower"
            for prev, nxt in zip(claim.rows, claim.rows[1:]):
                out.append((gid, nxt, claim.metric, prev, claim.metric, better, claim.strict))
        elif claim.kind == "greater":
            for r in claim.rows:
                out.append((gid, r, claim.metric_a, r, claim.metric_b, "higher", True))
        else:
            col = spec.group(gid).column(claim.metric)  # type: ignore[arg-type]
            better = claim.direction or (col.direction if col else "higher")
            out.append((gid, claim.rows[0], claim.metric, claim.rows[1], claim.metric, better, True))
    return out  # type: ignore[return-value]


def _paper_value(spec: TableSpec, row: str, gid: str, metric: str) -> float | None:
    r = next((x for x in spec.rows if x.label == row), None)
    return None if r is None or r.paper is None else r.paper.get(gid, {}).get(metric)


def check_claim(report: TableReport, claim: ClaimSpec) -> ClaimResult:
    """Check one claim on our means (and on the paper's values where the spec has them)."""
    spec = report.spec
    pairs = _pairs(spec, claim)
    missing = sorted({f"{r} [{g}] {m}" for g, ra, ma, rb, mb, _, _ in pairs
                      for r, m in ((ra, ma), (rb, mb)) if not report.cells[(r, g, m)].has_value})
    details: list[str] = []
    holds, partial = True, False
    for g, ra, ma, rb, mb, better, strict in pairs:
        ca, cb = report.cells[(ra, g, ma)], report.cells[(rb, g, mb)]
        if not (ca.has_value and cb.has_value):
            continue
        margin = claim.margin if claim.kind == "better" else 0.0
        ok = _compare(ca.mean - margin if better == "higher" else ca.mean + margin, cb.mean, better, strict)
        holds &= ok
        partial |= ca.status == "partial" or cb.status == "partial"
        spread = ca.std + cb.std
        if math.isfinite(spread):
            clear = "exceeds" if abs(ca.mean - cb.mean) > spread else "does NOT exceed"
            sp = f"|diff| {_fmt(abs(ca.mean - cb.mean))} {clear} the combined spread {_fmt(spread)}"
        else:
            sp = "spread unknown (one seed)"
        rel = (">" if better == "higher" else "<") + ("" if strict else "=") + (f" (by more than {_fmt(margin)})" if margin else "")
        details.append(
            f"[{g}] {ra} {ma} = {_fmt(ca.mean)} ± {_fmt(ca.std)} (n={ca.n}, {ca.n_seeds} seeds) "
            f"{rel} {rb} {mb} = {_fmt(cb.mean)} ± {_fmt(cb.std)} (n={cb.n}, {cb.n_seeds} seeds): "
            f"{'yes' if ok else 'NO'}; {sp}")
    unconverged = sorted({f"{r} [{g}]" for g, ra, _, rb, _, _, _ in pairs for r in (ra, rb) if report.not_converged(r, g)})
    if missing:
        verdict = f"UNDECIDED (missing rows: {'; '.join(missing)})"
    elif unconverged:
        verdict = f"UNDECIDED (not converged: {'; '.join(unconverged)}; as measured: {'HELD' if holds else 'NOT HELD'})"
    else:
        verdict = "HELD" if holds else "NOT HELD"
    paper_vals = [(_paper_value(spec, ra, g, ma), _paper_value(spec, rb, g, mb), better, strict)
                  for g, ra, ma, rb, mb, better, strict in pairs]
    if claim.margin and claim.kind == "better":
        paper_verdict = "n/a"  # a margin is our acceptance bar, not a claim of the paper
    elif all(a is not None and b is not None for a, b, _, _ in paper_vals):
        paper_verdict = "HELD" if all(_compare(a, b, bt, st) for a, b, bt, st in paper_vals) else "NOT HELD"  # type: ignore[arg-type]
    else:
        paper_verdict = "n/a"
    return ClaimResult(claim, verdict, details, paper_verdict, partial)


# --------------------------------------------------------------------------------------------------
# rendering


def _md_table(headers: list[str], rows: list[list[str]]) -> str:
    from tabulate import tabulate

    return tabulate(rows, headers=headers, tablefmt="pipe", disable_numparse=True)


def _num(x: float | None, fmt: str) -> str:
    return "-" if x is None or not math.isfinite(x) else format(x, fmt)


def _mean_total(report: TableReport, label: str, gid: str) -> str:
    t = report.timing
    sel = t[(t["row"] == label) & (t["group"] == gid) & (t["quantity"] == "total")]
    return "" if sel.empty else f"{sel['mean'].iloc[0]:.1f}"


def to_markdown(report: TableReport, heading_level: int = 2) -> str:
    """The table as markdown: ours ± std beside the paper's values, stage timings and claims."""
    spec, h = report.spec, "#" * heading_level
    multi = len(spec.groups) > 1
    headers = ["Method"]
    for g in spec.groups:
        prefix = f"{g.label} " if multi else ""
        headers += [f"{prefix}{c.label} {c.arrow}" + _unit_label(c) for c in g.columns]
        headers.append(f"{prefix}time [s]")
        if spec.convergence:
            headers.append(f"{prefix}converged")
    body: list[list[str]] = []
    for r in spec.rows:
        line = [f"**{r.label}**"]
        for g in spec.groups:
            for c in g.columns:
                line.append("(paper only)" if c.paper_only else format_cell(report.cells[(r.label, g.id, c.key)], c.fmt))
            line.append(_mean_total(report, r.label, g.id))
            if spec.convergence:
                line.append(report.convergence[(r.label, g.id)].label())
        if all(x in (NOT_IMPLEMENTED, "(paper only)", "", "-") for x in line[1:]):
            line = [line[0], NOT_IMPLEMENTED + f": `{r.method}`"] + [""] * (len(line) - 2)
        body.append(line)
        if r.paper:
            body.append(_paper_line(spec, f"↳ *paper: {r.paper_label or r.label}*", r.paper))
    for r in spec.paper_only_rows:
        body.append(_paper_line(spec, f"*paper: {r.label}*", r.paper or {}))
    n_exp = sum(c.n_expected for (lab, gid, key), c in report.cells.items()
                if key == next(x.key for x in spec.group(gid).columns if not x.paper_only))
    jobs = report.jobs
    parts = [
        f"{h} {spec.title}",
        "",
        f"Scale `{report.scale}`: {len(jobs[jobs['status'] == 'ok'])} ok, "
        f"{len(jobs[jobs['status'] == 'failed'])} failed, {n_exp - len(jobs)} pending of {n_exp} expected jobs"
        + (f"; {report.n_superseded} superseded result(s) ignored" if report.n_superseded else "")
        + (f"; {report.n_unmatched} result(s) of this table matching no row/group/scene/seed ignored"
           if report.n_unmatched else "") + ".",
        "",
        _md_table(headers, body),
        "",
        f"Bold rows: measured here, mean ± std over seeds (std: sample std, ddof=1, of the per-seed means "
        f"over scenes; none with one seed); `(k/N, ...)` marks cells with fewer than N scene x seed results. "
        f"Rows in *italics marked paper* are the values published in the paper{f' ({spec.paper_table})' if spec.paper_table else ''}, "
        f"not measured here; '-' = not published. Time: mean total wall seconds per job.",
    ]
    if spec.convergence:
        parts += ["", _convergence_sentence(spec)]
    if spec.notes:
        parts += [""] + [f"- {n}" for n in spec.notes]
    parts += ["", f"{h}# Stage timings (mean wall seconds per job)", "", _timing_markdown(report)]
    cost = _table_cost(report)
    if cost:
        parts += ["", cost]
    parts += ["", f"{h}# Claims", "", _claims_markdown(report)]
    failed = jobs[jobs["status"] == "failed"]
    if len(failed):
        parts += ["", f"{h}# Failed jobs", ""]
        for _, j in failed.head(20).iterrows():
            msg = str(j["error_message"] or "").splitlines()[0][:200] if j["error_message"] else ""
            parts.append(f"- {j['row']} [{j['gid']}] {j['scene']} seed {j['seed']}: {j['error_type']}: {msg} "
                         f"(`{Path(j['path']).name}`)")
        if len(failed) > 20:
            parts.append(f"- ... and {len(failed) - 20} more")
    return "\n".join(parts) + "\n"


def _convergence_sentence(spec: TableSpec) -> str:
    cv = spec.convergence
    assert cv is not None
    worse = "below" if cv.higher_is_better else "above"
    return (f"Converged (trained rows; `-` = no optimisation schedule): in every run {cv.metric} at the snapshot "
            f"nearest 50 % of the schedule is within {cv.flat:g} of the final value, no snapshot after 25 % is more "
            f"than {cv.drop:g} {worse} the one before, and the seed std of the final value is <= {cv.seed_std:g} "
            f"(`bench/convergence.py`). A row that has not converged is not a result: a claim comparing it is "
            f"UNDECIDED, with the verdict on the measured numbers in brackets.")


def _unit_label(c: Any) -> str:
    if c.published_unit != c.unit:
        return f" [{c.unit or '-'}; paper: {c.published_unit or '-'}]"
    return f" [{c.unit}]" if c.unit else ""


def _paper_line(spec: TableSpec, label: str, paper: Any) -> list[str]:
    line = [label]
    for g in spec.groups:
        vals = paper.get(g.id)
        for c in g.columns:
            fmt = c.fmt if c.published_unit == c.unit else "g"  # another unit: as published
            line.append("" if vals is None or c.key not in vals else _num(vals[c.key], fmt))
        line.append("")
        if spec.convergence:
            line.append("")
    return line


def _table_cost(report: TableReport) -> str:
    """One line: what the whole table costs on its own (sum of its successful jobs' wall seconds, each
    on the threads its worker had, and that sum over 2 workers), so runs with shared jobs can be budgeted."""
    ok = report.jobs[report.jobs["status"] == "ok"]
    if ok.empty:
        return ""
    total = pd.to_numeric(ok["timings"].map(lambda t: t.get("total")), errors="coerce").dropna()
    return (f"Table cost: {len(total)} jobs, {total.sum() / 60:.1f} job-minutes in total (sum of the jobs' wall "
            f"times, including those another table ran first); with 2 workers on 2 cores about "
            f"{total.sum() / 120:.1f} min of wall time.")


def _timing_markdown(report: TableReport) -> str:
    t = report.timing
    if t.empty:
        return "No finished jobs yet."
    multi = len(report.spec.groups) > 1
    quantities = list(dict.fromkeys(q for q in t["quantity"] if q not in ("total", "iterations")))
    quantities += [q for q in ("total", "iterations") if q in set(t["quantity"])]
    rows = []
    for (label, gid), sub in t.groupby(["row", "group"], sort=False):
        vals = dict(zip(sub["quantity"], sub["mean"]))
        name = f"{label} [{report.spec.group(gid).label}]" if multi else label
        rows.append([name] + [("" if q not in vals else f"{vals[q]:.0f}" if q == "iterations" else f"{vals[q]:.1f}")
                              for q in quantities])
    return _md_table(["Row"] + [q if q == "iterations" else f"{q} [s]" for q in quantities], rows)


def _claims_markdown(report: TableReport) -> str:
    if not report.claims:
        return "No claims in this table."
    lines = []
    for cr in report.claims:
        c = cr.claim
        note = " (on partial data: some cells miss results)" if cr.partial and not cr.verdict.startswith("UNDECIDED") else ""
        lines.append(f"- **{cr.verdict}**{note} `{c.id}`: {c.text} (paper's own values: {cr.paper_verdict})")
        lines += [f"    - {d}" for d in cr.details]
    return "\n".join(lines)


CURVE_COLUMNS = ["table", "row", "group", "fraction", "iterations", "seconds", "metric", "mean", "std", "n"]


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


def _curves(report: TableReport, curves: pd.DataFrame, gid: str, key: str) -> dict[str, tuple[list[float], list[float], tuple[float, float] | None]]:
    """Per row: mean (seconds, metric) per curve fraction (from ``curves``, :func:`curve_table`), and the
    mean final (total s, metric) point."""
    out = {}
    curves = curves[(curves["group"] == gid) & (curves["metric"] == key)].sort_values("fraction")
    ok = report.jobs[(report.jobs["status"] == "ok") & (report.jobs["gid"] == gid)]
    for label, sub in ok.groupby("row", sort=False):
        c = curves[curves["row"] == str(label)]
        total = pd.to_numeric(sub["timings"].map(lambda t: t.get("total")), errors="coerce")
        final = pd.to_numeric(sub["metrics"].map(lambda m: m.get(key)), errors="coerce")
        both = pd.DataFrame({"t": total, "v": final}).dropna()
        end = (float(both["t"].mean()), float(both["v"].mean())) if len(both) else None
        out[str(label)] = (c["seconds"].tolist(), c["mean"].tolist(), end)
    order = [r.label for r in report.spec.rows]
    return dict(sorted(out.items(), key=lambda kv: order.index(kv[0]) if kv[0] in order else len(order)))


def plot_accuracy_vs_time(report: TableReport, curves: pd.DataFrame | None = None) -> bytes:
    """PNG bytes: the main metric against wall seconds, one curve per row, one panel per group
    (``curves``: :func:`curve_table` of ``report`` when the caller has it already)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    _, main = report.spec.main_metric()
    groups = [g for g in report.spec.groups if g.column(main.key) is not None and not g.column(main.key).paper_only]  # type: ignore[union-attr]
    curves = curve_table(report) if curves is None else curves
    colours = {r.label: f"C{k % 10}" for k, r in enumerate(report.spec.rows)}  # one colour per row in every panel
    fig = Figure(figsize=(5.0 * len(groups), 3.8))
    FigureCanvasAgg(fig)
    for i, g in enumerate(groups):
        ax = fig.add_subplot(1, len(groups), i + 1)
        for label, (xs, ys, end) in _curves(report, curves, g.id, main.key).items():
            line = ax.plot(xs, ys, marker=".", label=label, color=colours.get(label))[0] if xs else None
            if end is not None:
                ax.plot([end[0]], [end[1]], marker="o", linestyle="", color=colours.get(label),
                        label=None if line else label)
        ax.set_xlabel("wall time [s]")
        ax.set_ylabel(f"{main.label} ({'higher' if main.direction == 'higher' else 'lower'} is better)")
        ax.set_title(f"{g.label}: {main.label} vs time ({report.scale})", fontsize=9)
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7)
        else:
            ax.text(0.5, 0.5, "no finished jobs yet", ha="center", va="center", transform=ax.transAxes)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    return buf.getvalue()


def write_table_outputs(report: TableReport, out_dir: str | Path, figures: bool = True) -> dict[str, Path]:
    """Write ``<table>.csv``, ``<table>_time.csv``, ``<table>_curve.csv`` (accuracy along the schedule,
    :func:`curve_table`), ``<table>.md`` and ``<table>_accuracy_vs_time.png`` atomically into
    ``out_dir``; with ``figures`` and kept meshes also ``<table>_reconstructions.png``
    (:func:`bench.figures.reconstruction_figure`), embedded in the markdown. Returns the paths by kind."""
    out, name = Path(out_dir), report.spec.name
    paths = {"csv": out / f"{name}.csv", "time_csv": out / f"{name}_time.csv", "curve_csv": out / f"{name}_curve.csv",
             "md": out / f"{name}.md", "png": out / f"{name}_accuracy_vs_time.png"}
    curves = curve_table(report)
    files: dict[Path, bytes] = {paths["csv"]: report.tidy.to_csv(index=False).encode(),
                                paths["time_csv"]: report.timing.to_csv(index=False).encode(),
                                paths["curve_csv"]: curves.to_csv(index=False).encode()}
    from bench.figures import reconstruction_figure, renders_figure, uncertainty_figure

    extra = ""
    for kind, make, caption in (
        ("reconstructions", reconstruction_figure, "Reconstructions (first scene, first seed of each group, from 2 training cameras): "
         "each pixel coloured by the distance of the surface it sees to the GT mesh (0-10 cm; grey: no surface)."),
        ("uncertainty", uncertainty_figure, "Estimated uncertainty beside the true error of the depth prior (|prior aligned "
         "to GT by per-view scale + shift - GT|), 3 views of the first scene and seed."),
        ("renders", renders_figure, "Test-view renders beside the GT images, rendered depth beside the GT depth "
         "(first scene and seed)."),
    ):
        png = make(report, out) if figures else None
        if png is not None:
            paths[f"{kind}_png"] = out / f"{name}_{kind}.png"
            files[paths[f"{kind}_png"]] = png
            extra += f"\n![{kind}]({paths[f'{kind}_png'].name})\n\n{caption}\n"
    files[paths["md"]] = (to_markdown(report, heading_level=1) + f"\n![accuracy vs time]({paths['png'].name})\n" + extra).encode()
    files[paths["png"]] = plot_accuracy_vs_time(report, curves)
    atomic_write_many(files)  # all of a table's outputs or none (a full disk leaves the previous set)
    return paths


def render_report(specs: Sequence[TableSpec], df: pd.DataFrame, scale: str, out_dir: str | Path,
                  available_methods: Iterable[str] | None = None, title: str = "MonoInstance benchmark report",
                  plans: Mapping[str, PlanIndex] | None = None) -> Path:
    """Build and write every table's outputs into ``out_dir`` and one ``report.md`` assembling them.

    ``plans``: per table name, its job ids (see :func:`build_table`). Returns the path of
    ``report.md``. Raises BenchInputError if a spec does not define ``scale``.
    """
    out = Path(out_dir)
    avail = None if available_methods is None else set(available_methods)
    reports = [build_table(s, df, scale, avail, None if plans is None else plans.get(s.name)) for s in specs]
    sections = [f"# {title}", "", f"Scale: `{scale}`. Jobs read: {len(df)}.", ""]
    if len(df):
        scales = sorted({str(v) for v in df["scale"].unique()})
        versions = sorted({f"{k} {v}" for vs in df["versions"] for k, v in vs.items()})
        sections.append(f"Scales present in the results: {', '.join(scales)}. "
                        f"Versions: {', '.join(versions) or 'not recorded'}.")
    sections += ["", "Tables:"] + [f"- [{r.spec.title}]({r.spec.name}.md)" for r in reports] + [""]
    for r in reports:
        paths = write_table_outputs(r, out)
        sections += [to_markdown(r, heading_level=2), f"![accuracy vs time]({r.spec.name}_accuracy_vs_time.png)", ""]
        sections += [f"![{k[:-4]}]({p.name})\n" for k, p in paths.items() if k.endswith("_png") and k != "png"]
    path = out / "report.md"
    atomic_write_text(path, "\n".join(sections))
    return path
