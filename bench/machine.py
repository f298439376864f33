"""What machine a result was measured on: the CPU model, recorded in every job row and printed by the benchmarks.

Times depend on it more than on most code changes: a VM's CPU can change between runs, and the same code took
72-82 s of training per small-preset SDF job on one AMD EPYC and 108-134 s on another (docs/performance.md). Metrics do not depend on it (every F identical in both runs)."""

from __future__ import annotations

import functools
import os
import platform
from pathlib import Path

CPUINFO = Path("/proc/cpuinfo")


def _cpuinfo_fields(text: str) -> dict[str, str]:
    """The first processor block of a /proc/cpuinfo text as {key: value}."""
    fields: dict[str, str] = {}
    for line in text.splitlines():
        if not line.strip():
            if fields:
                break
            continue
        key, _, value = line.partition(":")
        fields.setdefault(key.strip(), value.strip())
    return fields


def describe_cpu(cpuinfo_text: str | None, logical_cpus: int | None, fallback: str = "") -> str:
    """``"<model name> (family F model M), N logical CPUs"`` from a /proc/cpuinfo text; ``fallback`` (the platform's
    processor string) or ``"unknown CPU"`` without one. A VM's model name can be generic ("AMD EPYC"): the family and
    model numbers tell the generation apart."""
    f = _cpuinfo_fields(cpuinfo_text or "")
    name = f.get("model name") or fallback or "unknown CPU"
    ids = ", ".join(f"{label} {f[key]}" for key, label in (("cpu family", "family"), ("model", "model")) if key in f)
    count = f", {logical_cpus} logical CPUs" if logical_cpus else ""
    return f"{name}{f' ({ids})' if ids else ''}{count}"


@functools.lru_cache(maxsize=1)
def cpu_description() -> str:
    """This machine's CPU (:func:`describe_cpu` of /proc/cpuinfo where it exists)."""
    try:
        text: str | None = CPUINFO.read_text(encoding="utf-8", errors="replace")
    except OSError:
        text = None
    return describe_cpu(text, os.cpu_count(), platform.processor() or platform.machine())
