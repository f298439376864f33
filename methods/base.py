"""The interface between the harness and a method: ``Method.fit(scene, config, seed) -> Artifacts``.

A method sees only a :class:`bench.data.scene.Scene` (never a file format) and its resolved config dict. It
returns snapshots taken along its schedule (e.g. at 25 / 50 / 100 % of its iterations) so the harness
can show what accuracy costs in time, plus wall seconds per stage.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Protocol

import numpy as np

ProgressFn = Callable[[float, str], None]
"""``progress(fraction_done in [0, 1], message)``: called by long-running methods."""


@dataclass
class Snapshot:
    """The method's output at one point of its schedule.

    Attributes:
        fraction: fraction of the full schedule done (0-1].
        iterations: iterations (or views fused, ...) done so far.
        seconds: wall seconds spent in the method up to this snapshot (excluding evaluation).
        mesh: reconstructed surface (trimesh.Trimesh, world metres) for geometry methods, else None.
        renders: (M, H, W, 3) float32 renders of the scene's test views for view-synthesis methods, else None.
        depths: (M, H, W) float32 rendered z-depth (m, 0 = not covered) of the same test views, if the method has it.
        diagnostics: the method's own numbers at this point (JSON scalars), e.g. MonoSDF's beta, its
            loss terms averaged since the previous snapshot and the median rendered-depth error (m)
            against GT on training views; recorded in the result row's curve.
    """

    fraction: float
    iterations: int
    seconds: float
    mesh: Any = None
    renders: np.ndarray | None = None
    depths: np.ndarray | None = None
    diagnostics: dict[str, float] = field(default_factory=dict)


@dataclass
class Artifacts:
    """Everything a method run produced.

    Attributes:
        snapshots: ordered by fraction; the last one is the final result.
        timings: wall seconds per stage, e.g. ``{"train": 120.0, "mesh": 2.0}``.
        iterations: total iterations run.
        uncertainty: optional (N, H, W) float32 uncertainty maps in [0, 1] (1 = most uncertain).
        extra: free-form diagnostics recorded in the result row (must be JSON-serialisable).
    """

    snapshots: list[Snapshot]
    timings: dict[str, float] = field(default_factory=dict)
    iterations: int = 0
    uncertainty: np.ndarray | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def final(self) -> Snapshot:
        return self.snapshots[-1]


class Method(Protocol):
    """A reconstruction method. Implementations are registered with ``@register(name)``."""

    name: str

    def fit(self, scene: Any, config: dict[str, Any], seed: int, progress: ProgressFn | None = None) -> Artifacts:
        """Reconstruct ``scene`` with ``config``; deterministic for a given seed (within tolerance)."""
        ...
