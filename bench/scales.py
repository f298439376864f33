"""What each scale's numbers are: ``tiny`` is a smoke test, not a result.

The ``tiny`` preset (a few views at 80 x 60 px, a few hundred iterations, one seed) exists to check that a
table, a method or a dataset runs end to end in minutes; its trained rows stop long before any surface
forms (F-score ~0.01). Every output of a smoke-test scale says so: the table markdown and plot, the
claims (all UNDECIDED), the convergence column (no verdict), ``bench fit`` and ``bench study``.
"""

from __future__ import annotations

SMOKE_SCALES = frozenset({"tiny"})


def is_smoke(scale: str) -> bool:
    """True if results at ``scale`` only show that the pipeline runs (no verdict may be drawn from them)."""
    return scale in SMOKE_SCALES


def smoke_note(scale: str) -> str:
    """One sentence saying that ``scale`` is a smoke test (empty for a scale that gives results)."""
    if not is_smoke(scale):
        return ""
    return (f"Scale {scale!r} is a smoke test: it shows that the pipeline runs end to end; its numbers are not "
            f"results (trained rows stop long before convergence), so no convergence verdict and no claim is drawn from it.")
