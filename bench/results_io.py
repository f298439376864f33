"""Stored result rows -> one DataFrame: reading and validating the JSON per job in
``<results_dir>/jobs/`` that the runner writes (schema and required fields: :mod:`bench.jobs`).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pandas as pd

from bench.data.errors import BenchInputError
from bench.jobs import REQUIRED_FIELDS, RESULT_SCHEMA

RESULT_COLUMNS = [
    "job_id", "base_id", "table", "row", "method", "group", "dataset", "scene", "seed", "scale", "status",
    "error_type", "error_message", "metrics", "timings", "iterations", "curve", "config", "created",
    "worker", "versions", "cpu", "wall_seconds", "worker_name", "path",
]


def _read_job(path: Path) -> dict[str, Any]:
    try:
        d = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise BenchInputError(path, f"corrupt result JSON: {e}") from None
    if not isinstance(d, dict):
        raise BenchInputError(path, f"expected a JSON object, got {type(d).__name__}")
    missing = [k for k in REQUIRED_FIELDS if k not in d]
    if missing:
        raise BenchInputError(path, f"missing key(s) {missing}")
    if d.get("schema", RESULT_SCHEMA) != RESULT_SCHEMA:
        raise BenchInputError(path, f"schema {d.get('schema')!r} is not supported (expected {RESULT_SCHEMA})")
    if d["status"] not in ("ok", "failed"):
        raise BenchInputError(path, f"status: {d['status']!r} is not 'ok' or 'failed'")
    for key in ("metrics", "timings", "config"):
        if not isinstance(d.get(key) or {}, dict):
            raise BenchInputError(path, f"{key}: expected an object")
    if not isinstance(d.get("curve") or [], list):
        raise BenchInputError(path, "curve: expected a list")
    err = d.get("error") or {}
    try:
        seed = int(d["seed"])
    except (TypeError, ValueError):
        raise BenchInputError(path, f"seed: expected an integer, got {d['seed']!r}") from None
    return {
        "job_id": str(d["job_id"]), "base_id": str(d.get("base_id") or d["job_id"]), "table": str(d["table"]), "row": str(d["row"]),
        "method": str(d["method"]), "group": d.get("group"), "dataset": str(d["dataset"]),
        "scene": str(d["scene"]), "seed": seed, "scale": str(d["scale"]),
        "status": d["status"],
        "error_type": err.get("type") if isinstance(err, dict) else None,
        "error_message": err.get("message") if isinstance(err, dict) else str(err),
        "metrics": dict(d.get("metrics") or {}), "timings": dict(d.get("timings") or {}),
        "iterations": d.get("iterations"), "curve": list(d.get("curve") or []),
        "config": dict(d.get("config") or {}), "created": str(d.get("created") or ""),
        "worker": d.get("worker"), "versions": dict(d.get("versions") or {}),
        "cpu": d.get("cpu"), "wall_seconds": d.get("wall_seconds"), "worker_name": d.get("worker_name"), "path": str(path),
    }


def collect_results(results_dir: str | Path) -> pd.DataFrame:
    """One row per job JSON in ``<results_dir>/jobs/`` (columns :data:`RESULT_COLUMNS`).

    ``metrics``, ``timings``, ``config`` (dicts) and ``curve`` (list) stay Python objects. Hidden
    files (the atomic writer's temporaries) are skipped. A missing ``jobs/`` folder gives an empty
    frame; a corrupt or incomplete JSON raises :class:`BenchInputError` naming the file.
    """
    jobs = Path(results_dir) / "jobs"
    records = [_read_job(p) for p in sorted(jobs.glob("*.json")) if not p.name.startswith(".")] if jobs.is_dir() else []
    return pd.DataFrame.from_records(records, columns=RESULT_COLUMNS) if records else empty_results()


def empty_results() -> pd.DataFrame:
    """An empty results frame with the columns :func:`collect_results` returns."""
    return pd.DataFrame(columns=RESULT_COLUMNS)
