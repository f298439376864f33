"""One table as markdown: ours ± std beside the paper's values (with the ``converged`` column when the
spec judges convergence), the stage timings, the table's cost, the claims and the failed jobs.

A cell with fewer than ``n_expected`` values is marked, e.g. ``0.741 ± 0.010 (2/3, 1 failed)``, so a
partly failed row is never silently averaged over fewer jobs.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd

from bench.scales import is_smoke, smoke_note
from bench.table_report import Cell, TableReport
from bench.table_spec import TableSpec

NOT_IMPLEMENTED = "pending (method not implemented yet)"


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


def _md_table(headers: list[str], rows: list[list[str]]) -> str:
    from tabulate import tabulate

    return tabulate(rows, headers=headers, tablefmt="pipe", disable_numparse=True)


def _num(x: float | None, fmt: str) -> str:
    return "-" if x is None or not math.isfinite(x) else format(x, fmt)


def _mean_total(report: TableReport, label: str, gid: str) -> str:
    t = report.timing
    sel = t[(t["row"] == label) & (t["group"] == gid) & (t["quantity"] == "total")]
    return "" if sel.empty else f"{sel['mean'].iloc[0]:.1f}"


def _cpu_line(jobs: pd.DataFrame) -> str:
    """Which CPUs the jobs ran on (``bench.machine``): times vary with the VM's CPU, metrics do not."""
    cpus = jobs["cpu"].value_counts() if "cpu" in jobs else pd.Series(dtype=int)
    named = ", ".join(f"{cpu} ({n} job{'s' if n != 1 else ''})" for cpu, n in cpus.items() if cpu)
    missing = len(jobs) - int(cpus.sum())
    unknown = f"{', ' if named else ''}not recorded ({missing} job{'s' if missing != 1 else ''}, written before the field existed)" if missing else ""
    return f"Measured on: {named}{unknown}. Times depend on the CPU; the metrics do not."


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
        *([f"**Smoke test.** {smoke_note(report.scale)}", ""] if is_smoke(report.scale) else []),
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
    parts += ["", f"{h}# Stage timings (mean wall seconds per job)", "", _timing_markdown(report), "", _cpu_line(jobs)]
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
        lines.append(_claim_line(cr.verdict, note, c.id, c.text, cr.paper_verdict))
        lines += [f"    - {d}" for d in cr.details]
    lines += ["", "A claim is HELD when every comparison goes its way by more than the combined seed spread (std + std), "
              "NOT HELD when one goes against it by more than that; otherwise (also with one seed: spread unknown, and at "
              "a smoke-test scale) UNDECIDED, with the verdict on the measured means in brackets (`bench/claims.py`)."]
    return "\n".join(lines)


# One claim's line in a table's markdown; :func:`read_claims` parses it back (the README's glance reads published tables).
_CLAIM_LINE = re.compile(r"^- \*\*(?P<verdict>[^*]+)\*\*(?P<note> \(on partial data[^)]*\))? `(?P<id>[^`]+)`: (?P<text>.*) "
                         r"\(paper's own values: (?P<paper>[^()]*)\)$")


def _claim_line(verdict: str, note: str, claim_id: str, text: str, paper_verdict: str) -> str:
    return f"- **{verdict}**{note} `{claim_id}`: {text} (paper's own values: {paper_verdict})"


@dataclass(frozen=True)
class ClaimLine:
    """A claim's verdict as a table's markdown states it (:func:`read_claims`)."""

    id: str
    text: str
    verdict: str
    paper_verdict: str


def read_claims(markdown: str) -> list[ClaimLine]:
    """The claims of a table's markdown (as :func:`to_markdown` writes them), in order; [] without any."""
    found = (_CLAIM_LINE.match(line) for line in markdown.splitlines())
    return [ClaimLine(m["id"], m["text"], m["verdict"], m["paper"]) for m in found if m]
