"""Config overrides from the command line: ``--set KEY=VALUE ...`` and ``--sweep KEY=V1,V2,...``.

Shared by the CLI (``bench run``, ``bench study``, ``bench fit``, ``bench method``), the scripts and the
benchmarks; the values are checked later, against the method's typed config (``methods.registry``).
"""

from __future__ import annotations

from typing import Any

import yaml

from bench.data.errors import BenchInputError


def parse_value(text: str) -> Any:
    """A config value from the command line, parsed as YAML (``0.5`` -> float, ``true`` -> bool, ``[1, 2]``);
    ``1e-3``, which YAML 1.1 reads as a string, is a float too."""
    value = yaml.safe_load(text)
    if isinstance(value, str):
        try:
            return float(value)
        except ValueError:
            return value
    return value


def parse_overrides(items: list[str] | None, flag: str = "--set") -> dict[str, Any]:
    """``["KEY=VALUE", ...]`` -> ``{key: parsed value}`` (:func:`parse_value`); a malformed item is a
    BenchInputError naming ``flag``."""
    out: dict[str, Any] = {}
    for item in items or []:
        if "=" not in item:
            raise BenchInputError(flag, f"expected KEY=VALUE, got {item!r}")
        key, value = item.split("=", 1)
        out[key.strip()] = parse_value(value)
    return out


def parse_sweep(text: str | None) -> tuple[str | None, list[Any]]:
    """``KEY=V1,V2,...`` -> (key, [values]); None -> (None, [None])."""
    if not text:
        return None, [None]
    if "=" not in text:
        raise BenchInputError("--sweep", f"expected KEY=V1,V2,..., got {text!r}")
    key, vals = text.split("=", 1)
    values = [parse_value(v) for v in vals.split(",") if v.strip()]
    if not values:
        raise BenchInputError("--sweep", f"no values for {key!r}")
    return key.strip(), values
