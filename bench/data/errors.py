"""One error type for bad input, so the CLI can print a single clear line naming the file and the problem."""

from __future__ import annotations

from pathlib import Path


class BenchInputError(ValueError):
    """Bad user input: a missing or malformed file, a bad recipe or config value.

    The message always names the offending file (or config key) and the problem, e.g.
    ``scene/cameras.npz: world_mat_3 is not invertible``.
    """

    def __init__(self, where: str | Path, problem: str) -> None:
        self.where = str(where)
        self.problem = problem
        super().__init__(f"{self.where}: {problem}")
