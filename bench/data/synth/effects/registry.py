"""The effect registry and :func:`apply_effects`, the one entry point the synthesizer calls."""

from __future__ import annotations

import inspect
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from bench.data.errors import BenchInputError
from bench.data.scene import Scene

from ._params import params_to_record, parse_params

# An effect modifies the scene in place, drawing randomness only from ``rng``. It may return a small
# JSON-serialisable dict of what it drew per view (e.g. the per-view scales), recorded as "sampled".
EffectFn = Callable[[Scene, Any, np.random.Generator], "dict[str, Any] | None"]


@dataclass(frozen=True)
class EffectSpec:
    """A registered effect.

    Attributes:
        name: the name recipes use.
        fn: ``fn(scene, params, rng)``; modifies ``scene`` in place.
        params_cls: frozen dataclass of typed parameters with defaults (see ``_params.param``).
        needs: Scene fields that must be present (not None) for the effect to run.
        expands: for a composite effect (a preset list of other effects, e.g. ``prior_profile``):
            ``expands(params) -> (label, effect list)``; the list is validated and applied in its place
            and recorded under ``"expanded"``. Composites do not nest. None for a plain effect.
    """

    name: str
    fn: EffectFn
    params_cls: type
    needs: tuple[str, ...] = ()
    expands: Callable[[Any], "tuple[str, list[dict[str, Any]]]"] | None = None

    @property
    def doc(self) -> str:
        return inspect.getdoc(self.fn) or ""

    def defaults(self) -> dict[str, Any]:
        """Every parameter with its default value (JSON form)."""
        return params_to_record(self.params_cls())


EFFECTS: dict[str, EffectSpec] = {}


def register(name: str, params_cls: type, needs: tuple[str, ...] = (),
             expands: Callable[[Any], "tuple[str, list[dict[str, Any]]]"] | None = None) -> Callable[[EffectFn], EffectFn]:
    """Decorator registering ``fn`` under ``name`` with its parameter dataclass (``expands``: see
    :class:`EffectSpec`)."""

    def deco(fn: EffectFn) -> EffectFn:
        if name in EFFECTS:
            raise RuntimeError(f"effect {name!r} registered twice")
        EFFECTS[name] = EffectSpec(name, fn, params_cls, tuple(needs), expands)
        return fn

    return deco


@dataclass(frozen=True)
class _Planned:
    """One validated effect: spec + parsed params, or a composite with its expansion."""

    spec: EffectSpec
    params: Any
    expanded: tuple["_Planned", ...] = ()


def _plan(effects: Any, where: str, *, inside_profile: str | None = None) -> list[_Planned]:
    if effects is None:
        return []
    if not isinstance(effects, (list, tuple)):
        raise BenchInputError(where, f"effects must be a list of effect dicts (got {type(effects).__name__})")
    plan = []
    for i, entry in enumerate(effects):
        ctx = f"effects[{i}]" if inside_profile is None else f"profile '{inside_profile}' effects[{i}]"
        if not isinstance(entry, dict):
            raise BenchInputError(where, f"{ctx} must be a dict with a 'name' (got {entry!r})")
        name = entry.get("name")
        if not isinstance(name, str):
            raise BenchInputError(where, f"{ctx} has no 'name' string (got {entry!r})")
        if name not in EFFECTS:
            known = ", ".join(sorted(EFFECTS))
            raise BenchInputError(where, f"unknown effect '{name}' in {ctx} (known: {known})")
        spec = EFFECTS[name]
        raw = {k: v for k, v in entry.items() if k != "name"}
        params = parse_params(name, spec.params_cls, raw, where)
        expanded: tuple[_Planned, ...] = ()
        if spec.expands is not None:
            if inside_profile is not None:
                raise BenchInputError(where, f"effect '{name}' cannot be nested (in profile '{inside_profile}')")
            label, effects_list = spec.expands(params)
            expanded = tuple(_plan(effects_list, where, inside_profile=label))
        plan.append(_Planned(spec, params, expanded))
    return plan


def _check_needs(scene: Scene, planned: _Planned, where: str) -> None:
    for field_name in planned.spec.needs:
        if getattr(scene, field_name) is None:
            raise BenchInputError(where, f"effect '{planned.spec.name}' needs scene.{field_name}, which is None")
    for sub in planned.expanded:
        _check_needs(scene, sub, where)


def _run(scene: Scene, planned: _Planned, rng: np.random.Generator) -> dict[str, Any]:
    record: dict[str, Any] = {"name": planned.spec.name, **params_to_record(planned.params)}
    if planned.expanded:
        record["expanded"] = [_run(scene, sub, rng) for sub in planned.expanded]
        return record
    sampled = planned.spec.fn(scene, planned.params, rng)
    if sampled:
        record["sampled"] = sampled
    return record


def apply_effects(
    scene: Scene, effects: list[dict[str, Any]] | None, rng: np.random.Generator, where: str | Path = "effects"
) -> list[dict[str, Any]]:
    """Apply a recipe's effects to ``scene`` in the listed order, in place.

    Every entry is validated (name, parameters, profile expansion, required scene fields) before any
    effect runs, so a bad recipe leaves the scene untouched.

    Args:
        scene: the scene to modify (priors usually initialised to exact ground truth).
        effects: list of dicts ``{"name": <effect>, <param>: <value>, ...}``; None or [] = no effect.
        rng: the only source of randomness; same scene + effects + seed -> identical arrays.
        where: file or key named in error messages (the recipe path).

    Returns:
        One JSON-serialisable record per effect: ``{"name", <every parameter incl. defaults>}`` plus
        ``"sampled"`` (per-view draws, where the effect reports them) or, for ``prior_profile``,
        ``"expanded"`` (the records of the effects the profile expanded to). Removing ``"sampled"``
        and ``"expanded"`` gives back a valid recipe entry.

    Raises:
        BenchInputError: unknown effect / parameter, wrong type, out-of-range value, missing field.
    """
    where = str(where)
    if not isinstance(rng, np.random.Generator):
        raise BenchInputError(where, f"apply_effects needs a numpy Generator as rng (got {type(rng).__name__})")
    plan = _plan(effects, where)
    for planned in plan:
        _check_needs(scene, planned, where)
    return [_run(scene, planned, rng) for planned in plan]
