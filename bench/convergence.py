"""When does a trained row count as a result: the convergence criteria of the issue tracker.

A run is one (scene, seed) job. Its curve is the metric at the snapshots along its schedule
(``fraction`` of the iterations done, e.g. 0.25 / 0.5 / 1.0). Per run:

* ``flat``: the value at the snapshot nearest 50 % of the schedule is within ``flat`` of the final one;
* ``no_drop``: no snapshot after 25 % is worse than the one before by more than ``drop`` ("worse" in the
  metric's direction: lower for F-score, higher for an error).

Per row (all runs of one table row in one column group): every run flat and without a drop, and the
seed spread of the final value (sample std over seeds of the per-seed mean over scenes, the table's
``±``) at most ``seed_std``. With one seed the spread is unknown and only the per-run checks decide.

Only optimised rows are judged: a job counts as trained when its resolved config sets ``iterations``
(an optimisation schedule; :func:`bench.jobs.is_trained`, which the runner's "training first" order uses too). Fusion references (the oracle's snapshots count views fused) have none.
Used by :mod:`bench.aggregate` (the verdict per row), :mod:`bench.claims` and :mod:`bench.study` (``bench study convergence``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Iterable, Sequence

import numpy as np

from bench.jobs import is_trained


@dataclass(frozen=True)
class ConvergenceSpec:
    """The criteria (metric units): see the module docstring. ``higher_is_better`` is the metric's
    direction (True for F-score)."""

    metric: str = "fscore"
    flat: float = 0.03
    drop: float = 0.05
    seed_std: float = 0.03
    higher_is_better: bool = True


@dataclass(frozen=True)
class RunCheck:
    """One run's checks: ``half`` the value at the snapshot nearest 50 %, ``final`` the last one,
    ``max_drop`` the largest worsening between consecutive snapshots after 25 % (>= 0)."""

    flat: bool
    no_drop: bool
    half: float
    final: float
    max_drop: float


def check_run(fractions: Sequence[float] | np.ndarray, values: Sequence[float] | np.ndarray, spec: ConvergenceSpec) -> RunCheck:
    """The per-run checks on one curve (any order; NaN = a snapshot without that metric).

    A run whose final value is missing passes neither check; a NaN neighbour skips that drop."""
    fr = np.asarray(fractions, dtype=float)
    v = np.asarray(values, dtype=float)
    order = np.argsort(fr, kind="stable")
    fr, v = fr[order], v[order]
    if not len(v) or not np.isfinite(v[-1]):
        return RunCheck(False, False, math.nan, math.nan, math.nan)
    half = float(v[int(np.argmin(np.abs(fr - 0.5)))])
    sign = 1.0 if spec.higher_is_better else -1.0
    drops = [sign * (v[i - 1] - v[i]) for i in range(1, len(v))
             if fr[i] > 0.25 + 1e-9 and np.isfinite(v[i - 1]) and np.isfinite(v[i])]
    max_drop = max([0.0, *drops])
    flat = bool(np.isfinite(half) and abs(half - v[-1]) <= spec.flat)
    return RunCheck(flat, bool(max_drop <= spec.drop), half, float(v[-1]), float(max_drop))


@dataclass(frozen=True)
class RowConvergence:
    """The verdict on one row (one column group): ``n_runs`` trained runs judged, how many are flat /
    without a drop, the seed spread of the final value (NaN with one seed)."""

    spec: ConvergenceSpec
    n_runs: int
    n_flat: int
    n_no_drop: int
    seed_std: float
    smoke: bool = False  # a smoke-test scale (bench.scales): the row is not judged at all

    @property
    def judged(self) -> bool:
        """False for rows without a trained run (fusion references, rows with no results) and at a smoke-test scale."""
        return self.n_runs > 0 and not self.smoke

    @property
    def converged(self) -> bool:
        spread_ok = not math.isfinite(self.seed_std) or self.seed_std <= self.spec.seed_std
        return self.judged and self.n_flat == self.n_runs and self.n_no_drop == self.n_runs and spread_ok

    def reasons(self) -> list[str]:
        """What fails, in words (empty when converged or not judged)."""
        out = []
        if self.n_flat < self.n_runs:
            out.append(f"flat {self.n_flat}/{self.n_runs}")
        if self.n_no_drop < self.n_runs:
            out.append(f"no drop {self.n_no_drop}/{self.n_runs}")
        if math.isfinite(self.seed_std) and self.seed_std > self.spec.seed_std:
            out.append(f"seed std {self.seed_std:.3f} > {self.spec.seed_std:g}")
        return out

    def label(self) -> str:
        """Short text for a table cell: ``yes``, ``yes (one seed)``, ``NO (flat 2/6, ...)``, ``-`` or
        ``n/a (smoke test)``."""
        if self.smoke:
            return "n/a (smoke test)"
        if not self.judged:
            return "-"
        if self.converged:
            return "yes" if math.isfinite(self.seed_std) else "yes (spread unknown: one seed)"
        return f"NO ({', '.join(self.reasons())})"


def _number(x: Any) -> float:
    """A stored metric value as a float (NaN for None or a non-number)."""
    try:
        return math.nan if x is None or isinstance(x, bool) else float(x)
    except (TypeError, ValueError):
        return math.nan


def judge_row(runs: Iterable[tuple[int, Sequence[dict[str, Any]], Any]], spec: ConvergenceSpec) -> RowConvergence:
    """The row verdict from its successful runs: ``(seed, curve, config)`` each, ``curve`` the job's
    snapshot list (dicts with ``fraction`` and ``metrics``). Untrained runs are skipped."""
    checks: list[RunCheck] = []
    finals: dict[int, list[float]] = {}
    for seed, curve, config in runs:
        if not is_trained(config):
            continue
        pts = [p for p in curve if isinstance(p, dict) and p.get("fraction") is not None]
        vals = [_number((p.get("metrics") or {}).get(spec.metric)) for p in pts]
        c = check_run([float(p["fraction"]) for p in pts], vals, spec)
        checks.append(c)
        if math.isfinite(c.final):
            finals.setdefault(int(seed), []).append(c.final)
    per_seed = [float(np.mean(v)) for v in finals.values()]
    std = float(np.std(per_seed, ddof=1)) if len(per_seed) > 1 else math.nan
    return RowConvergence(spec, len(checks), sum(c.flat for c in checks), sum(c.no_drop for c in checks), std)
