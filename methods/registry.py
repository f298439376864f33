"""The method registry: one place where methods are declared (see ``methods/__init__.py``)."""

from __future__ import annotations

import copy
import difflib
import functools
import importlib
import json
from pathlib import Path
from typing import Any, Callable, NamedTuple

import yaml

from bench.data.config import load_config
from bench.data.errors import BenchInputError

_REGISTRY: dict[str, type] = {}
CONFIG_DIR = Path(__file__).resolve().parent.parent / "configs" / "methods"


def register(name: str) -> Callable[[type], type]:
    """Class decorator: ``@register("oracle_tsdf")`` adds the class to the registry."""

    def deco(cls: type) -> type:
        if name in _REGISTRY and _REGISTRY[name] is not cls:
            raise ValueError(f"method {name!r} registered twice")
        setattr(cls, "name", name)  # noqa: B010 (the attribute is the registry's, set on any class)
        _REGISTRY[name] = cls
        return cls

    return deco


PLUGIN_GROUP = "monoinstance_bench.methods"
_PLUGIN_CONFIGS: dict[str, Path] = {}
_plugins_loaded = False


def builtin_modules() -> list[str]:
    """The modules of the ``methods`` package that declare a method (a line starting with
    ``@register(``), found by reading the sources: adding a method needs no list kept by hand, and
    modules that declare none (networks, losses, kernels) are not imported for it."""
    root = Path(__file__).resolve().parent
    found = []
    for path in sorted(root.rglob("*.py")):
        if path.name != "registry.py" and any(line.lstrip().startswith("@register(") for line in path.read_text().splitlines()):
            found.append(".".join(("methods", *path.relative_to(root).with_suffix("").parts)))
    return found


def _load_builtins() -> None:
    for mod in builtin_modules():
        importlib.import_module(mod)
    _load_plugins()


def _load_plugins() -> None:
    """Methods from installed packages: every entry point of the group :data:`PLUGIN_GROUP`
    (``name = "package.module:Class"``) registers ``Class`` under ``name``; the class says where its
    config lives (``config_path``: a YAML of the same shape as ``configs/methods/*.yaml``). Example:
    ``examples/plugin_method`` (docs/usage.md, "Your own method")."""
    global _plugins_loaded
    if _plugins_loaded:
        return
    _plugins_loaded = True
    from importlib.metadata import entry_points

    for ep in entry_points(group=PLUGIN_GROUP):
        try:
            cls = ep.load()
        except Exception as exc:  # a broken plugin must name itself, not crash the harness with a traceback
            raise BenchInputError(f"plugin {ep.name!r} ({ep.value})", f"cannot be loaded: {type(exc).__name__}: {exc}") from None
        config = getattr(cls, "config_path", None)
        if config is None or not Path(config).is_file():
            raise BenchInputError(f"plugin {ep.name!r} ({ep.value})", f"needs a config_path attribute naming its YAML config, got {config!r}")
        register(ep.name)(cls)
        _PLUGIN_CONFIGS[ep.name] = Path(config)


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


def config_type(name: str) -> type | None:
    """The typed config class of method ``name`` (its ``config_type`` attribute; None for a plugin that
    declares none: its config then stays an unchecked mapping)."""
    _load_builtins()
    if name not in _REGISTRY:
        raise BenchInputError(f"method {name!r}", f"not in the registry (available: {sorted(_REGISTRY)})")
    return getattr(_REGISTRY[name], "config_type", None)


class _MethodYaml(NamedTuple):
    """A method's YAML config with ``base:`` inheritance resolved."""

    path: Path
    defaults: dict[str, Any]
    scales: dict[str, dict[str, Any]]
    id_neutral: dict[str, Any]  # keys left out of job ids at these values (:func:`identity_config`)


def _yaml_file(path: Path) -> dict[str, Any]:
    """A YAML file's data (a copy: callers may change it), parsed once per version of the file: planning a
    table resolves one config per job, and 500 seeds re-parsed the same files thousands of times (23 s)."""
    st = path.stat()
    return copy.deepcopy(_parsed_yaml(str(path), st.st_mtime_ns, st.st_size))


@functools.lru_cache(maxsize=128)
def _parsed_yaml(path: str, mtime_ns: int, size: int) -> dict[str, Any]:
    return yaml.safe_load(Path(path).read_text()) or {}


def _read_config(name: str, config_dir: Path) -> _MethodYaml:
    """``configs/methods/<name>.yaml`` (a plugin's own ``config_path``), with ``base:`` inheritance resolved."""
    _load_plugins()
    path = _PLUGIN_CONFIGS.get(name) or config_dir / f"{name}.yaml"
    if not path.exists():
        known = available_methods()
        unknown = "" if name in known else f": not a known method (known: {', '.join(known)})"
        raise BenchInputError(path, f"no config file for method {name!r}{unknown}")
    data = _yaml_file(path)
    defaults = dict(data.get("defaults") or {})
    scales = {k: dict(v or {}) for k, v in (data.get("scales") or {}).items()}
    neutral = dict(data.get("id_neutral") or {})
    if data.get("base"):
        base = _read_config(str(data["base"]), config_dir)
        defaults = {**base.defaults, **defaults}
        scales = {k: {**base.scales.get(k, {}), **scales.get(k, {})} for k in set(base.scales) | set(scales)}
        neutral = {**base.id_neutral, **neutral}
    return _MethodYaml(path, defaults, scales, neutral)


def identity_config(name: str, config: dict[str, Any], config_dir: Path = CONFIG_DIR) -> dict[str, Any]:
    """The part of a resolved config that identifies a job (hashed into its id by ``bench.runner``).

    A method's YAML may list ``id_neutral: {key: value}``: keys added after results were published whose
    value there reproduces the code from before the key existed (e.g. ``use_grid: true``). At exactly that
    value the key is left out of the identity, so published job rows keep matching their plans; at any
    other value it is part of it. The full config is still what the method receives and what is stored."""
    neutral = _read_config(name, config_dir).id_neutral
    return {k: v for k, v in config.items() if not (k in neutral and json.dumps(v) == json.dumps(neutral[k]))}


def method_config(name: str, scale: str, overrides: dict[str, Any] | None = None, config_dir: Path = CONFIG_DIR) -> dict[str, Any]:
    """Resolve a method's config: ``defaults`` <- ``scales[scale]`` <- ``overrides`` (later wins).

    ``configs/methods/<name>.yaml`` has the shape ``{description, base (optional), defaults: {...},
    scales: {tiny: {...}, ...}}``; ``base: other`` inherits the other method's defaults and scale presets
    (a variant family shares one training loop and one config, not a copy). Overrides may only name
    keys that exist in ``defaults`` (a typo is an error, not a silent no-op). The result is checked
    against the method's typed config (:func:`config_type`: every key declared, every value of its
    type and range), so a bad preset or override fails here, naming the YAML file, before any job runs.

    Returns the resolved mapping (JSON-serialisable: it is hashed into the job id and stored with the
    result); :func:`typed_method_config` gives the typed object.
    """
    path, defaults, scales, _ = _read_config(name, config_dir)
    if scale not in scales:
        raise BenchInputError(path, f"no preset for scale {scale!r} (has {sorted(scales)})")
    cfg = {**defaults, **scales[scale]}
    for key, value in (overrides or {}).items():
        if key not in defaults:
            near = difflib.get_close_matches(str(key), list(defaults), n=1, cutoff=0.5)
            hint = f"; did you mean {near[0]!r}?" if near else ""
            raise BenchInputError(path, f"override {key!r} is not a config key of {name!r}{hint} (keys: {sorted(defaults)})")
        cfg[key] = value
    ctype = config_type(name)
    if ctype is not None:
        load_config(ctype, cfg, f"{path} (scale {scale!r}" + (f", overrides {sorted(overrides)})" if overrides else ")"))
    return cfg


def typed_method_config(name: str, scale: str, overrides: dict[str, Any] | None = None, config_dir: Path = CONFIG_DIR) -> Any:
    """:func:`method_config` as the method's typed config object (its :func:`config_type`)."""
    cfg = method_config(name, scale, overrides, config_dir)
    ctype = config_type(name)
    if ctype is None:
        raise BenchInputError(f"method {name!r}", "declares no config_type (a plugin): use method_config")
    return load_config(ctype, cfg, f"method {name!r} config")
