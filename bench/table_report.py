"""What one table's report holds (data only): the :class:`Cell` of every row x group x metric, the
:class:`ClaimResult` of every claim, and the :class:`TableReport` that carries them with the matched
jobs, the tidy and timing frames and the convergence verdicts.

Built by :func:`bench.report.build_table` (statistics: :mod:`bench.aggregate`, claims: :mod:`bench.claims`);
read by the markdown (:mod:`bench.table_markdown`), the figures (:mod:`bench.figures`) and ``bench regress``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import pandas as pd

from bench.convergence import RowConvergence
from bench.table_spec import ClaimSpec, TableSpec


@dataclass(frozen=True)
class Cell:
    """Aggregate of one row x group x metric over seeds and scenes (the statistics: :mod:`bench.aggregate`)."""

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
    tidy: pd.DataFrame  # bench.aggregate.TIDY_COLUMNS
    timing: pd.DataFrame  # bench.aggregate.TIME_COLUMNS
    claims: list[ClaimResult]
    unavailable: set[str]
    n_unmatched: int = 0
    n_superseded: int = 0
    convergence: dict[tuple[str, str], RowConvergence] = field(default_factory=dict)  # (row, group) -> verdict; empty without a spec

    def not_converged(self, label: str, gid: str) -> bool:
        """True if the row was judged in this group and has not converged."""
        v = self.convergence.get((label, gid))
        return v is not None and v.judged and not v.converged
