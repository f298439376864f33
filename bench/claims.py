"""The claims check: each claim of a table spec (:class:`bench.table_spec.ClaimSpec`) judged on the
table's cell means, and on the paper's own values where the spec has them.

A claim compares means. For each comparison we also say whether the difference exceeds the combined
spread ``std_a + std_b`` (a deliberately conservative test; unknown with one seed). A claim is HELD only
if every comparison goes its way by more than that spread, and NOT HELD only if one goes against it by
more than that spread; otherwise it is ``UNDECIDED (within the seed spread: ...; as measured: ...)``.
Measured reason: the Table 3 runs of two rasteriser kernels that differ only in float
rounding gave every claim of that table opposite verdicts, every difference inside the spread (Gaussian
densification is chaotic to rounding; docs/studies/gaussian-rasteriser-and-llff-runs.md). With one seed the spread is unknown, so no
difference can be shown to exceed it: ``UNDECIDED (spread unknown, one seed: ...)``.

Convergence: a claim comparing a row that has not converged (the verdicts of
:func:`bench.aggregate.judge_rows`, :mod:`bench.convergence`) is ``UNDECIDED (not converged: ...)``:
a row that has not converged is not a result. At a smoke-test scale (:mod:`bench.scales`) every claim is
``UNDECIDED (smoke test at scale ...)``.
"""

from __future__ import annotations

import math

from bench.scales import is_smoke
from bench.table_report import ClaimResult, TableReport
from bench.table_spec import ClaimSpec, TableSpec


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
    unresolved: list[str] = []  # comparisons whose difference does not exceed the combined spread
    one_seed: list[str] = []  # comparisons with a one-seed cell: the spread is unknown
    clear_miss = False  # a comparison against the claim by more than the combined spread
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
            beyond = abs(ca.mean - cb.mean) > spread
            clear = "exceeds" if beyond else "does NOT exceed"
            if not beyond:
                unresolved.append(f"{ra} {ma} vs {rb} {mb} [{g}]")
            clear_miss |= beyond and not ok
            sp = f"|diff| {_fmt(abs(ca.mean - cb.mean))} {clear} the combined spread {_fmt(spread)}"
        else:
            one_seed.append(f"{ra} {ma} vs {rb} {mb} [{g}]")
            sp = "spread unknown (one seed)"
        rel = (">" if better == "higher" else "<") + ("" if strict else "=") + (f" (by more than {_fmt(margin)})" if margin else "")
        details.append(
            f"[{g}] {ra} {ma} = {_fmt(ca.mean)} ± {_fmt(ca.std)} (n={ca.n}, {ca.n_seeds} seeds) "
            f"{rel} {rb} {mb} = {_fmt(cb.mean)} ± {_fmt(cb.std)} (n={cb.n}, {cb.n_seeds} seeds): "
            f"{'yes' if ok else 'NO'}; {sp}")
    unconverged = sorted({f"{r} [{g}]" for g, ra, _, rb, _, _, _ in pairs for r in (ra, rb) if report.not_converged(r, g)})
    measured = f"as measured: {'HELD' if holds else 'NOT HELD'}"
    if missing:
        verdict = f"UNDECIDED (missing rows: {'; '.join(missing)})"
    elif is_smoke(report.scale):
        verdict = f"UNDECIDED (smoke test at scale {report.scale!r}: not a result; {measured})"
    elif unconverged:
        verdict = f"UNDECIDED (not converged: {'; '.join(unconverged)}; {measured})"
    elif (unresolved or one_seed) and not clear_miss:
        why = ([f"within the seed spread: {'; '.join(unresolved)}"] if unresolved else []) \
            + ([f"spread unknown, one seed: {'; '.join(one_seed)}"] if one_seed else [])
        verdict = f"UNDECIDED ({'; '.join(why)}; {measured})"
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
