"""Reconstruction methods, declared in one registry.

Adding a method (the whole procedure):

1. Write a module in ``methods/`` with a class implementing :class:`methods.base.Method`
   (``fit(scene, config, seed, progress) -> Artifacts``) and decorate it with
   ``@register("my_method")``.
   The registry finds the module itself (``methods.registry.builtin_modules``).
2. Add ``configs/methods/my_method.yaml`` with its default config and per-scale presets.
3. Use it as a row in a table spec (``configs/tables/*.yaml``): ``{label: ..., method: my_method,
   overrides: {...}}``. Variants are config overrides of one method, never copies.
"""

from methods.base import Artifacts, Method, Snapshot
from methods.registry import available_methods, get_method, register

__all__ = ["Artifacts", "Method", "Snapshot", "available_methods", "get_method", "register"]
