"""Regression against stored reference results: ``bench regress --table NAME [--scale small]``.

A fresh run of the table (every job rerun: job ids carry the package version, not the commit, so
stored results could be stale) is aggregated exactly as the table is (:func:`bench.report.build_table`)
and compared with ``results/reference/<scale>/<table>.json``, per row x group x metric (the measured
columns of the table spec; their ``direction`` says which way is worse).

Reference file (written only with ``--update-reference``, refused when a job failed)::

    {"schema": 1, "table": "ablation", "scale": "small", "created": "...", "versions": {...},
     "tolerance": {"k": 3.0, "floors": {"acc": 0.002, "fscore": 0.01, ...}},
     "cells": {"<row label>": {"<group id>": {"<metric>": {"mean": .., "std": .., "n": .., "n_expected": ..,
                                                         "direction": "lower", "unit": "m"}}}}}

Extra metrics of a group (``extra_metrics``: e.g. the uncertainty stage's ``unc_mean_thin``, which only
a row with the uncertainty module produces) have no direction: they are tracked for presence only, so a
module that stops running (its metric disappears) is ``missing`` and fails the run.

Verdict per cell, with ``tol = max(floor[metric], k * std_ref)`` (``std_ref``: the seed-to-seed
spread stored in the reference; 0 with one seed) and ``worse = new - ref`` for "lower is better"
(``ref - new`` for "higher"):

* ``regressed`` if ``worse > tol`` (fails);
* ``improved`` if ``-worse > tol`` (reported; passes; consider ``--update-reference``);
* ``ok`` otherwise;
* ``failed`` if any job of the cell failed, ``missing`` if the cell has fewer results than the
  table expects or no value (fails: a row in the reference must not disappear);
* ``no_reference`` for a cell the reference does not have (e.g. a method that was pending when the
  reference was made; passes, reported), and ``pending`` for rows whose method is not implemented
  yet and which the reference does not have either (passes, not run).

The command exits 1 if any cell regressed, failed or is missing, else 0; bad input exits 2.
Tolerance floors default per unit (:data:`DEFAULT_FLOORS`, overridable per metric in
:data:`METRIC_FLOORS`) and are stored in the reference file, so changing them is a reviewed edit.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Iterable, Literal

from bench.data.atomic import atomic_write_json, atomic_write_text
from bench.data.errors import BenchInputError
from bench.executors.base import Executor
from bench.jobs import versions
from bench.pipeline import SHIPPED_TABLES, load_tables, plan_table
from bench.table_spec import TableSpec

REFERENCE_SCHEMA = 1
DEFAULT_K = 3.0
# absolute floors of the tolerance by the column's unit, then by metric name (these win)
DEFAULT_FLOORS: dict[str, float] = {"m": 0.002, "mm": 2.0, "dB": 0.2, "": 0.01}
METRIC_FLOORS: dict[str, float] = {"psnr": 0.2, "ssim": 0.01, "nc": 0.01, "fscore": 0.01}
FALLBACK_FLOOR = 0.01
Verdict = Literal["ok", "improved", "regressed", "failed", "missing", "no_reference", "pending"]
FAILING: tuple[str, ...] = ("regressed", "failed", "missing")


@dataclass(frozen=True)
class Finding:
    """The comparison of one row x group x metric."""

    row: str
    group: str
    metric: str
    verdict: Verdict
    ref_mean: float | None = None
    ref_std: float | None = None
    new_mean: float | None = None
    new_std: float | None = None
    n: int | None = None
    n_expected: int | None = None
    tol: float | None = None
    note: str = ""

    @property
    def fails(self) -> bool:
        return self.verdict in FAILING


@dataclass
class RegressResult:
    """All findings of one table at one scale; ``passed`` is False if any finding fails."""

    table: str
    scale: str
    findings: list[Finding]

    @property
    def passed(self) -> bool:
        return not any(f.fails for f in self.findings)

    def by_verdict(self, *verdicts: str) -> list[Finding]:
        return [f for f in self.findings if f.verdict in verdicts]


def _num(x: Any) -> float | None:
    return None if x is None or (isinstance(x, float) and not math.isfinite(x)) else float(x)


def floor_for(metric: str, unit: str) -> float:
    """The default absolute tolerance floor of ``metric`` (measured in ``unit``)."""
    return METRIC_FLOORS.get(metric, DEFAULT_FLOORS.get(unit, FALLBACK_FLOOR))


def summarise(spec: TableSpec, report, rows: Iterable[str] | None = None) -> dict[str, Any]:
    """Per row x group x measured column of ``report`` (a :class:`bench.table_report.TableReport`):
    mean, std, n, n_expected, n_failed, status, direction, unit. Rows of methods that are not
    implemented (and have no results), rows outside ``rows`` (when given) and metrics a method does not
    report are left out."""
    cells: dict[str, dict[str, dict[str, Any]]] = {}
    keep = None if rows is None else set(rows)
    for r in spec.rows:
        if keep is not None and r.label not in keep:
            continue
        for g in spec.groups:
            tracked: list[tuple[str, str | None, str]] = [(c.key, c.direction, c.unit) for c in g.columns if not c.paper_only]
            tracked += [(key, None, "") for key in g.extra_metrics]  # presence only (no direction)
            for key, direction, unit in tracked:
                cell = report.cells.get((r.label, g.id, key))
                if cell is None or cell.status in ("not_implemented", "not_reported"):
                    continue  # no results expected / the method does not produce this metric
                cells.setdefault(r.label, {}).setdefault(g.id, {})[key] = {
                    "mean": _num(cell.mean), "std": _num(cell.std), "n": int(cell.n),
                    "n_expected": int(cell.n_expected), "n_failed": int(cell.n_failed),
                    "status": cell.status, "direction": direction, "unit": unit}
    return cells


def make_reference(spec: TableSpec, report, versions: dict[str, str] | None = None, k: float = DEFAULT_K,
                   rows: Iterable[str] | None = None) -> dict[str, Any]:
    """A reference document from a fresh run's report (see the module docstring for the format).

    Raises BenchInputError if any job of the run failed or is missing: a reference must be complete.
    """
    cells = summarise(spec, report, rows)
    bad = [f"{row} [{gid}] {m}: {v['status']} ({v['n']}/{v['n_expected']}, {v['n_failed']} failed)"
           for row, gs in cells.items() for gid, ms in gs.items() for m, v in ms.items()
           if v["n_failed"] or v["n"] < v["n_expected"]]
    if bad:
        raise BenchInputError(spec.path or spec.name, "refusing to store a reference with failed or missing jobs: "
                              + "; ".join(bad[:5]))
    floors = {c.key: floor_for(c.key, c.unit) for g in spec.groups for c in g.columns if not c.paper_only}
    for gs in cells.values():
        for ms in gs.values():
            for v in ms.values():
                for key in ("n_failed", "status"):
                    v.pop(key)
    return {"schema": REFERENCE_SCHEMA, "table": spec.name, "scale": report.scale,
            "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
            "versions": dict(versions or {}), "tolerance": {"k": k, "floors": floors}, "cells": cells}


def compare(reference: dict[str, Any], current: dict[str, Any], pending_rows: Iterable[str] = ()) -> list[Finding]:
    """Compare a current summary (:func:`summarise`) with a reference document (:func:`make_reference`).

    ``pending_rows``: labels of rows whose method is not implemented (no results expected).
    """
    tol_cfg = reference.get("tolerance") or {}
    k = float(tol_cfg.get("k", DEFAULT_K))
    floors = dict(tol_cfg.get("floors") or {})
    ref_cells = reference.get("cells") or {}
    pending = set(pending_rows)
    out: list[Finding] = []
    for row, gs in ref_cells.items():
        for gid, ms in gs.items():
            for metric, ref in ms.items():
                cur = ((current.get(row) or {}).get(gid) or {}).get(metric)
                rm, rs = _num(ref.get("mean")), _num(ref.get("std"))
                base = dict(row=row, group=gid, metric=metric, ref_mean=rm, ref_std=rs)
                if cur is None:
                    why = "method not implemented any more" if row in pending else "no results"
                    out.append(Finding(**base, verdict="missing", note=f"in the reference, {why} now"))
                    continue
                nm = _num(cur.get("mean"))
                base.update(new_mean=nm, new_std=_num(cur.get("std")), n=cur.get("n"), n_expected=cur.get("n_expected"))
                if cur.get("n_failed"):
                    out.append(Finding(**base, verdict="failed", note=f"{cur['n_failed']} job(s) failed"))
                    continue
                if nm is None or rm is None or cur.get("n", 0) < cur.get("n_expected", 0):
                    out.append(Finding(**base, verdict="missing",
                                       note=f"{cur.get('n', 0)}/{cur.get('n_expected', '?')} results ({cur.get('status')})"))
                    continue
                direction = ref.get("direction", cur.get("direction"))
                if direction is None:  # an extra metric (e.g. a module's own output): tracked for presence
                    out.append(Finding(**base, verdict="ok", note=f"present (extra metric, no direction; was {_f(rm)})"))
                    continue
                floor = float(floors.get(metric, floor_for(metric, ref.get("unit", ""))))
                tol = max(floor, k * (rs or 0.0))
                worse = (nm - rm) if direction == "lower" else (rm - nm)
                verdict: Verdict = "regressed" if worse > tol else ("improved" if -worse > tol else "ok")
                out.append(Finding(**base, verdict=verdict, tol=tol,
                                   note=f"{'worse' if worse > 0 else 'better'} by {abs(worse):.4g} (tolerance {tol:.4g})"))
    for row, gs in current.items():
        for gid, ms in gs.items():
            for metric, cur in ms.items():
                if metric in ((ref_cells.get(row) or {}).get(gid) or {}):
                    continue
                base = dict(row=row, group=gid, metric=metric, new_mean=_num(cur.get("mean")),
                            new_std=_num(cur.get("std")), n=cur.get("n"), n_expected=cur.get("n_expected"))
                if cur.get("n_failed"):  # a failed job is a failure even without a reference
                    out.append(Finding(**base, verdict="failed", note=f"{cur['n_failed']} job(s) failed (no reference yet)"))
                else:
                    out.append(Finding(**base, verdict="no_reference", note="no reference yet"))
    for row in sorted(pending - set(ref_cells)):
        out.append(Finding(row=row, group="*", metric="*", verdict="pending",
                           note="method not implemented yet; no reference yet"))
    return out


def _f(x: float | None) -> str:
    return "-" if x is None else f"{x:.4g}"


def to_markdown(result: RegressResult) -> str:
    """A short report: the verdict, then failing cells, improvements, and the rest."""
    head = "PASSED" if result.passed else "FAILED"
    lines = [f"# Regression: table `{result.table}`, scale `{result.scale}`: {head}", ""]
    counts = {v: len(result.by_verdict(v)) for v in ("regressed", "failed", "missing", "improved", "ok", "no_reference", "pending")}
    lines.append(", ".join(f"{n} {v}" for v, n in counts.items() if n) or "nothing compared")
    lines += ["", "| verdict | row | group | metric | reference (mean ± std) | now (mean ± std) | n | tolerance | note |",
              "|---|---|---|---|---|---|---|---|---|"]
    order = {v: i for i, v in enumerate(("regressed", "failed", "missing", "improved", "no_reference", "pending", "ok"))}
    for f in sorted(result.findings, key=lambda f: (order[f.verdict], f.row, f.group, f.metric)):
        n = "-" if f.n is None else f"{f.n}/{f.n_expected}"
        lines.append(f"| {f.verdict} | {f.row} | {f.group} | {f.metric} | {_f(f.ref_mean)} ± {_f(f.ref_std)} "
                     f"| {_f(f.new_mean)} ± {_f(f.new_std)} | {n} | {_f(f.tol)} | {f.note} |")
    return "\n".join(lines) + "\n"


def reference_path(reference_dir: str | Path, scale: str, table: str) -> Path:
    return Path(reference_dir) / scale / f"{table}.json"


def load_reference(path: Path) -> dict[str, Any]:
    try:
        d = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as e:
        raise BenchInputError(path, f"cannot read the reference: {e}") from None
    if not isinstance(d, dict) or d.get("schema") != REFERENCE_SCHEMA or not isinstance(d.get("cells"), dict):
        raise BenchInputError(path, f"not a reference file of schema {REFERENCE_SCHEMA} (with 'cells')")
    return d


def run_regress(args: argparse.Namespace, executor: Executor, tables_dir: Path = SHIPPED_TABLES) -> int:
    """``bench regress``: fresh run(s) on ``executor``, comparison or reference update, report; returns
    the exit code. ``args``: the CLI's (``table``, ``scale``, ``out``, ``reference_dir``, ...)."""
    from bench.report import build_table, write_table_outputs
    from bench.results_io import collect_results
    from bench.runner import plan_index, run_jobs
    from methods.registry import available_methods

    specs = load_tables(args.table, tables_dir)
    out = Path(args.out) / args.scale
    failed_tables: list[str] = []
    for spec in specs:
        ref_path = reference_path(args.reference_dir, args.scale, spec.name)
        reference = load_reference(ref_path) if ref_path.exists() else None
        if reference is None and not args.update_reference:
            print(f"table {spec.name}: no reference yet at {ref_path} (create it with --update-reference); skipped")
            continue
        rows = getattr(args, "rows", None)
        source = getattr(args, "from_results", None)
        planned = plan_table(spec, args.scale, rows, threads=None if source is not None else executor.planned_threads)
        jobs, pending = planned.jobs, planned.pending
        if source is not None:  # no fresh run: the stored results of an earlier `bench run` (same ids)
            df = collect_results(Path(source) / args.scale)
            print(f"table {spec.name}: {len(jobs)} jobs read from {Path(source) / args.scale} (no fresh run)")
        else:
            print(f"table {spec.name}: fresh run of {len(jobs)} jobs at scale {args.scale!r} on {executor.describe()}")
            run_jobs(jobs, out, force=True, show_progress=not args.quiet, executor=executor)
            df = collect_results(out)
        df = df[df["base_id"].isin({j.base_id for j in jobs})]
        report = build_table(spec, df, args.scale, available_methods(), plans=plan_index(jobs))
        write_table_outputs(report, out)
        if args.update_reference:
            doc = make_reference(spec, report, versions(), rows=rows)
            atomic_write_json(ref_path, doc)
            print(f"table {spec.name}: stored the reference {ref_path} (the fresh table in {out})")
            if reference is not None:
                findings = compare(reference, summarise(spec, report, rows))
                changed = [f for f in findings if f.verdict not in ("ok",)]
                print(f"  (against the previous reference: {len(changed)} cell(s) changed beyond tolerance or new)")
            continue
        pending_rows = sorted({p.row for p in pending} | ({r.label for r in spec.rows} - set(rows) if rows else set()))
        assert reference is not None  # no reference and no --update-reference: skipped above
        result = RegressResult(spec.name, args.scale, compare(reference, summarise(spec, report, rows), pending_rows))
        md = to_markdown(result)
        atomic_write_text(out / f"regress_{spec.name}.md", md)
        atomic_write_json(out / f"regress_{spec.name}.json",
                          {"table": spec.name, "scale": args.scale, "passed": result.passed,
                           "reference": str(ref_path), "findings": [asdict(f) for f in result.findings]})
        print(md)
        print(f"table {spec.name}: {'passed' if result.passed else 'REGRESSION'}; report {out / f'regress_{spec.name}.md'} "
              f"(and .json), the fresh table beside it in {out}")
        if not result.passed:
            failed_tables.append(spec.name)
    if failed_tables:
        print(f"REGRESSION in {', '.join(failed_tables)} (reports in {out})")
        return 1
    return 0
