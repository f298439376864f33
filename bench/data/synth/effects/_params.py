"""Typed effect parameters: declaration (a dataclass field per parameter) and validation.

Each effect declares its parameters as a frozen dataclass whose fields are made with :func:`param`,
which records the kind (``float``, ``int``, ``bool``, ``range``, ``choice``), the allowed interval,
the unit and a one-line description. :func:`parse_params` turns a recipe dict into that dataclass or
raises one :class:`~bench.data.errors.BenchInputError` naming the effect, the parameter and the problem.
Values are checked by the harness's one config core (:func:`bench.data.config.check_value` on the
annotation a spec stands for, :func:`annotation_of`); the spec adds units and docs for docs/effects.md.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Annotated, Any, Literal

from bench.data.config import Range, check_value
from bench.data.errors import BenchInputError

KINDS = ("float", "int", "bool", "range", "choice")


@dataclass(frozen=True)
class ParamSpec:
    """How one parameter is checked and documented.

    ``lo``/``hi`` bound the value (for ``range``: both ends of the pair); ``lo_open``/``hi_open`` make
    the bound strict. ``choices`` lists the allowed strings of a ``choice`` parameter.
    """

    kind: str
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    hi_open: bool = False
    choices: tuple[str, ...] = ()
    unit: str = ""
    doc: str = ""

    def describe(self) -> str:
        """Human-readable constraint, e.g. ``"a number in [0, 1]"``."""
        if self.kind == "bool":
            return "true or false"
        if self.kind == "choice":
            return "one of " + ", ".join(repr(c) for c in self.choices)
        what = {"float": "a number", "int": "an integer", "range": "a pair [low, high] of numbers with low <= high"}[
            self.kind
        ]
        bounds = self._interval()
        if bounds:
            what += (", each" if self.kind == "range" else "") + " in " + bounds
        return what

    def _interval(self) -> str:
        if self.lo is None and self.hi is None:
            return ""
        left = "(" if (self.lo is None or self.lo_open) else "["
        right = ")" if (self.hi is None or self.hi_open) else "]"
        lo = "-inf" if self.lo is None else _fmt(self.lo)
        hi = "inf" if self.hi is None else _fmt(self.hi)
        return f"{left}{lo}, {hi}{right}"


def _fmt(x: float) -> str:
    return str(int(x)) if float(x).is_integer() else repr(float(x))


def param(
    default: Any,
    kind: str,
    *,
    lo: float | None = None,
    hi: float | None = None,
    lo_open: bool = False,
    hi_open: bool = False,
    choices: tuple[str, ...] = (),
    unit: str = "",
    doc: str = "",
) -> Any:
    """A dataclass field carrying its :class:`ParamSpec` in ``metadata["spec"]``."""
    assert kind in KINDS, kind
    spec = ParamSpec(kind, lo, hi, lo_open, hi_open, tuple(choices), unit, doc)
    return field(default=default, metadata={"spec": spec})


def spec_of(f: dataclasses.Field) -> ParamSpec:
    return f.metadata["spec"]


def _is_number(x: Any) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def annotation_of(spec: ParamSpec) -> Any:
    """The :mod:`bench.data.config` annotation a parameter's spec stands for (one checking core for
    every config of the harness; the spec adds the unit and the one-line doc for docs/effects.md)."""
    bounds = Range(spec.lo, spec.hi, spec.lo_open, spec.hi_open)
    if spec.kind == "bool":
        return bool
    if spec.kind == "choice":
        return Literal[tuple(spec.choices)]  # type: ignore[valid-type]
    if spec.kind == "int":
        return Annotated[int, bounds]
    if spec.kind == "float":
        return Annotated[float, bounds]
    return tuple[Annotated[float, bounds], Annotated[float, bounds]]  # range


def _check_value(effect: str, name: str, spec: ParamSpec, value: Any, where: str) -> Any:
    """Validate one value against its spec; return it normalised (float, int, bool, tuple, str)."""
    pair = (value, value) if spec.kind == "range" and _is_number(value) else value  # x means the range [x, x]
    try:
        out = check_value(annotation_of(spec), pair)
    except ValueError:
        out = None
    if out is None or (spec.kind == "range" and out[0] > out[1]):
        raise BenchInputError(where, f"effect '{effect}': parameter '{name}' must be {spec.describe()} (got {value!r})")
    return out


def parse_params(effect: str, cls: type, raw: dict[str, Any], where: str) -> Any:
    """Build the parameter dataclass ``cls`` of ``effect`` from a recipe dict (without ``"name"``).

    Raises:
        BenchInputError: unknown parameter, wrong type or out-of-range value.
    """
    fields = {f.name: f for f in dataclasses.fields(cls)}
    for key in raw:
        if key not in fields:
            known = ", ".join(sorted(fields)) or "none"
            raise BenchInputError(where, f"effect '{effect}': unknown parameter '{key}' (known: {known})")
    values = {}
    for name, f in fields.items():
        if name in raw:
            values[name] = _check_value(effect, name, spec_of(f), raw[name], where)
    params = cls(**values)
    check = getattr(params, "check", None)
    if check is not None:  # cross-parameter constraints
        problem = check()
        if problem:
            raise BenchInputError(where, f"effect '{effect}': {problem}")
    return params


def params_to_record(params: Any) -> dict[str, Any]:
    """JSON-serialisable dict of every parameter (tuples become lists)."""
    out: dict[str, Any] = {}
    for f in dataclasses.fields(params):
        v = getattr(params, f.name)
        out[f.name] = list(v) if isinstance(v, tuple) else v
    return out


def params_table(cls: type) -> list[dict[str, str]]:
    """Rows (name, kind, default, constraint, unit, doc) for documentation."""
    rows = []
    for f in dataclasses.fields(cls):
        s = spec_of(f)
        d = list(f.default) if isinstance(f.default, tuple) else f.default
        rows.append(
            {"name": f.name, "kind": s.kind, "default": repr(d), "constraint": s.describe(), "unit": s.unit, "doc": s.doc}
        )
    return rows
