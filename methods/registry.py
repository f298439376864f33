"""The method registry: one place where methods are declared (see ``methods/__init__.py``)."""

from __future__ import annotations

import importlib
from pathlib import Path
from typing import Any, Callable

import yaml

from bench.errors import BenchInputError

_REGISTRY: dict[str, type] = {}
_BUILTIN_MODULES = ("methods.oracle_tsdf", "methods.monosdf.method", "methods.monoinstance.method",
                    "methods.gaussians.methods")
CONFIG_DIR = Path(__file__).resolve().parent.parent / "configs" / "methods"


def register(name: str) -> Callable[[type], type]:
    """Class decorator: ``@register("oracle_tsdf")`` adds the class to the registry."""

    def deco(cls: type) -> type:
        if name in _REGISTRY and _REGISTRY[name] is not cls:
            raise ValueError(f"method {name!r} registered twice")
        cls.name = name
        _REGISTRY[name] = cls
        return cls

    return deco


def _load_builtins() -> None:
    for mod in _BUILTIN_MODULES:
        importlib.import_module(mod)


def available_methods() -> list[str]:
    """Names of all registered methods."""
    _load_builtins()
    return sorted(_REGISTRY)


def get_method(name: str) -> Any:
    """Instantiate the method registered as ``name``."""
    _load_builtins()
    if name not in _REGISTRY:
        raise BenchInputError(f"method {name!r}", f"not in the registry (available: {sorted(_REGISTRY)})")
    return _REGISTRY[name]()


def _read_config(name: str, config_dir: Path) -> tuple[Path, dict[str, Any], dict[str, Any]]:
    """(path, defaults, scales) of ``configs/methods/<name>.yaml``, with ``base:`` inheritance resolved."""
    path = config_dir / f"{name}.yaml"
    if not path.exists():
        raise BenchInputError(path, f"no config file for method {name!r}")
    data = yaml.safe_load(path.read_text()) or {}
    defaults = dict(data.get("defaults") or {})
    scales = {k: dict(v or {}) for k, v in (data.get("scales") or {}).items()}
    if data.get("base"):
        _, base_defaults, base_scales = _read_config(str(data["base"]), config_dir)
        defaults = {**base_defaults, **defaults}
        scales = {k: {**base_scales.get(k, {}), **scales.get(k, {})} for k in set(base_scales) | set(scales)}
    return path, defaults, scales


def method_config(name: str, scale: str, overrides: dict[str, Any] | None = None, config_dir: Path = CONFIG_DIR) -> dict[str, Any]:
    """Resolve a method's config: ``defaults`` <- ``scales[scale]`` <- ``overrides`` (later wins).

    ``configs/methods/<name>.yaml`` has the shape ``{description, base (optional), defaults: {...},
    scales: {tiny: {...}, ...}}``; ``base: other`` inherits the other method's defaults and scale presets
    (a variant family shares one training loop and one config, not a copy). Overrides may only name
    keys that exist in ``defaults`` (a typo is an error, not a silent no-op).
    """
    path, defaults, scales = _read_config(name, config_dir)
    if scale not in scales:
        raise BenchInputError(path, f"no preset for scale {scale!r} (has {sorted(scales)})")
    cfg = {**defaults, **scales[scale]}
    for key, value in (overrides or {}).items():
        if key not in defaults:
            raise BenchInputError(path, f"override {key!r} is not a config key of {name!r} (keys: {sorted(defaults)})")
        cfg[key] = value
    return cfg
