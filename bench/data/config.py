"""The one typed-config mechanism: frozen dataclasses filled from YAML mappings.

A config is a frozen dataclass whose annotations are the schema. :func:`load_config` fills it from a
mapping (a YAML preset after inheritance and overrides) and raises one
:class:`~bench.data.errors.BenchInputError` naming the file and the key path for

* a key the dataclass does not declare (a typo is an error, never a silent no-op),
* a declared key without a value and without a dataclass default,
* a value of the wrong type (``1e-4`` in YAML 1.1 is a *string*: caught here), or outside its
  :class:`Range` (``Annotated[float, Range(lo=0)]``).

Where the values live: a method's values are its YAML preset (``configs/methods/<name>.yaml``); its
dataclass declares names and types only (no second set of defaults in the code). Small configs that
have no YAML of their own (effect parameters, protocol options) may give dataclass defaults instead:
either way a value is written down in exactly one place.

Supported annotations: ``bool``, ``int``, ``float`` (an int is accepted and converted), ``str``,
``None``, ``Literal[...]``, unions (``X | None``), ``tuple[X, ...]`` / ``tuple[X, Y]`` (a YAML list
becomes a tuple), ``dict[str, X]``, ``Any``, nested config dataclasses, and ``Annotated[X, Range(...)]``.
"""

from __future__ import annotations

import dataclasses
import math
import types
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal, TypeVar, Union, get_args, get_origin, get_type_hints

from bench.data.errors import BenchInputError

T = TypeVar("T")


@dataclass(frozen=True)
class Range:
    """Bounds of a number: ``Annotated[float, Range(lo=0, lo_open=True)]`` is a positive float."""

    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    hi_open: bool = False

    def holds(self, x: float) -> bool:
        if not math.isfinite(x):
            return False
        if self.lo is not None and (x <= self.lo if self.lo_open else x < self.lo):
            return False
        return not (self.hi is not None and (x >= self.hi if self.hi_open else x > self.hi))

    def describe(self) -> str:
        left = "(" if (self.lo is None or self.lo_open) else "["
        right = ")" if (self.hi is None or self.hi_open) else "]"
        lo = "-inf" if self.lo is None else f"{self.lo:g}"
        hi = "inf" if self.hi is None else f"{self.hi:g}"
        return f"in {left}{lo}, {hi}{right}"


# The bounds the typed configs of the methods share (``Annotated[float, Positive]``).
Positive = Range(lo=0, lo_open=True)
NonNegative = Range(lo=0)
Fraction = Range(lo=0, hi=1)  # of a training schedule, a probability, a share
AtLeastOne = Range(lo=1)


class _Mismatch(Exception):
    """A value does not fit its annotation (internal; becomes a BenchInputError with the key path)."""

    def __init__(self, key: str, expected: str, value: Any) -> None:
        super().__init__(key)
        self.key, self.expected, self.value = key, expected, value


def describe_type(tp: Any) -> str:
    """Human-readable form of an annotation, for error messages: ``tuple[float, ...]`` -> "a list of numbers"."""
    origin, args = get_origin(tp), get_args(tp)
    if tp is Any:
        return "anything"
    if tp is type(None) or tp is None:
        return "null"
    if tp is bool:
        return "true or false"
    if tp is int:
        return "an integer"
    if tp is float:
        return "a number"
    if tp is str:
        return "a string"
    if origin is Annotated:
        extra = " ".join(m.describe() for m in tp.__metadata__ if isinstance(m, Range))
        return f"{describe_type(args[0])} {extra}".strip()
    if origin is Literal:
        return "one of " + ", ".join(repr(a) for a in args)
    if origin in (Union, types.UnionType):
        return " or ".join(describe_type(a) for a in args)
    if origin is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            return f"a list of ({describe_type(args[0])})"
        return "a list [" + ", ".join(describe_type(a) for a in args) + "]"
    if origin in (dict, Mapping):
        return "a mapping"
    if isinstance(tp, type) and dataclasses.is_dataclass(tp):
        return f"a mapping of {tp.__name__} keys"
    return getattr(tp, "__name__", str(tp))


def _convert(tp: Any, value: Any, key: str, where: str) -> Any:
    """``value`` checked against annotation ``tp`` and normalised (int -> float, list -> tuple)."""
    origin, args = get_origin(tp), get_args(tp)
    if tp is Any:
        return value
    if origin is Annotated:
        try:
            out = _convert(args[0], value, key, where)
        except _Mismatch as bad:
            raise (_Mismatch(key, describe_type(tp), value) if bad.key == key else bad) from None
        for meta in tp.__metadata__:
            if isinstance(meta, Range) and not meta.holds(float(out)):
                raise _Mismatch(key, describe_type(tp), value)
        return out
    if tp is type(None) or tp is None:
        if value is None:
            return None
        raise _Mismatch(key, "null", value)
    if tp is bool:
        if isinstance(value, bool):
            return value
        raise _Mismatch(key, describe_type(tp), value)
    if tp is int:
        if isinstance(value, int) and not isinstance(value, bool):
            return int(value)
        raise _Mismatch(key, describe_type(tp), value)
    if tp is float:
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return float(value)
        raise _Mismatch(key, describe_type(tp), value)
    if tp is str:
        if isinstance(value, str):
            return value
        raise _Mismatch(key, describe_type(tp), value)
    if origin is Literal:
        if any(value == a and type(value) is type(a) for a in args):
            return value
        raise _Mismatch(key, describe_type(tp), value)
    if origin in (Union, types.UnionType):
        options = [a for a in args if a is not type(None)]
        if value is None and len(options) < len(args):
            return None
        if len(options) == 1:  # X | None with a value: X's own (deepest) error, e.g. the bad entry of a mapping
            try:
                return _convert(options[0], value, key, where)
            except _Mismatch as bad:
                if bad.key != key:
                    raise
                raise _Mismatch(key, describe_type(tp), value) from None
        for option in options:
            try:
                return _convert(option, value, key, where)
            except _Mismatch:
                continue
        raise _Mismatch(key, describe_type(tp), value)
    if origin is tuple:
        if not isinstance(value, (list, tuple)):
            raise _Mismatch(key, describe_type(tp), value)
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_convert(args[0], v, f"{key}[{i}]", where) for i, v in enumerate(value))
        if len(value) != len(args):
            raise _Mismatch(key, describe_type(tp), value)
        return tuple(_convert(a, v, f"{key}[{i}]", where) for i, (a, v) in enumerate(zip(args, value)))
    if origin in (dict, Mapping):
        if not isinstance(value, Mapping):
            raise _Mismatch(key, describe_type(tp), value)
        kt, vt = args if args else (Any, Any)
        return {_convert(kt, k, key, where): _convert(vt, v, f"{key}.{k}", where) for k, v in value.items()}
    if isinstance(tp, type) and dataclasses.is_dataclass(tp):
        if not isinstance(value, Mapping):
            raise _Mismatch(key, describe_type(tp), value)
        return _fill(tp, value, where, prefix=f"{key}.")
    raise TypeError(f"config annotation {tp!r} of {key!r} is not supported by bench.data.config")


def _fill(cls: type[T], data: Mapping[str, Any], where: str, prefix: str = "") -> T:
    fields = {f.name: f for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    hints = get_type_hints(cls, include_extras=True)
    owner = "" if cls.__name__.startswith("_") else f" of {cls.__name__}"  # private records: the key path says enough
    unknown = sorted(set(data) - set(fields))
    if unknown:
        raise BenchInputError(where, f"unknown config key '{prefix}{unknown[0]}'{owner} (known: {', '.join(sorted(fields))})")
    values: dict[str, Any] = {}
    for name, f in fields.items():
        if name in data:
            try:
                values[name] = _convert(hints[name], data[name], prefix + name, where)
            except _Mismatch as bad:
                raise BenchInputError(where, f"config key {bad.key!r} must be {bad.expected} (got {bad.value!r})") from None
        elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            raise BenchInputError(where, f"config key '{prefix}{name}'{owner} has no value")
    obj = cls(**values)
    problem = obj.check() if hasattr(obj, "check") else None
    if problem:
        raise BenchInputError(where, f"{prefix.rstrip('.') or cls.__name__}: {problem}")
    return obj


def load_config(cls: type[T], data: Mapping[str, Any], where: str | Path, key: str = "") -> T:
    """Fill the frozen config dataclass ``cls`` from ``data`` (see the module docstring for the rules).

    A dataclass may define ``check(self) -> str | None`` for constraints between keys: a returned
    string is the problem, raised like any other. ``key`` is the mapping's own path inside ``where``
    (e.g. ``datasets[0].columns[1]``): messages then name ``datasets[0].columns[1].fmt``.

    Raises:
        BenchInputError: ``where`` (the YAML file or a description) plus the key path and the problem.
    """
    if not isinstance(data, Mapping):
        raise BenchInputError(where, f"{key + ': ' if key else ''}expected a mapping of {cls.__name__} keys, got {type(data).__name__}")
    return _fill(cls, data, str(where), prefix=f"{key}." if key else "")


def check_value(annotation: Any, value: Any) -> Any:
    """One value checked against an annotation (the rules of :func:`load_config`) and normalised.

    Raises:
        ValueError: the value does not fit; the message describes what was expected.
    """
    try:
        return _convert(annotation, value, "value", "")
    except _Mismatch as bad:
        raise ValueError(f"must be {bad.expected} (got {bad.value!r})") from None


def config_record(obj: Any) -> dict[str, Any]:
    """JSON-serialisable dict of a config dataclass (tuples become lists, nested configs dicts)."""

    def plain(v: Any) -> Any:
        if dataclasses.is_dataclass(v) and not isinstance(v, type):
            return {f.name: plain(getattr(v, f.name)) for f in dataclasses.fields(v)}
        if isinstance(v, (list, tuple)):
            return [plain(x) for x in v]
        if isinstance(v, dict):
            return {k: plain(x) for k, x in v.items()}
        return v

    return plain(obj)


def field_names(cls: type) -> tuple[str, ...]:
    """The keys a config dataclass declares, in declaration order."""
    return tuple(f.name for f in dataclasses.fields(cls))


__all__ = ["Range", "load_config", "check_value", "config_record", "field_names", "describe_type"]
