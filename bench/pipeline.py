"""Plan -> run -> collect: the steps ``bench run``, ``bench report`` and ``bench regress`` share.

A table spec (:mod:`bench.table_spec`) becomes job plans (:func:`plan_jobs`: rows x groups x scenes x
seeds), filtered by the CLI's options (:func:`select_plans`) and resolved into runnable jobs with ids
(:func:`plan_table`).

Paths are arguments (``tables_dir``: where table names resolve, default :data:`SHIPPED_TABLES`), never
module state a caller has to patch. Executors are the caller's (the CLI builds one from its flags).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Sequence

from bench.data.errors import BenchInputError
from bench.jobs import Job, JobPlan
from bench.runner import resolve_jobs
from bench.table_spec import TableSpec, list_tables, load_table_spec, resolve

REPO_ROOT = Path(__file__).resolve().parent.parent
SHIPPED_TABLES = REPO_ROOT / "configs" / "tables"


def table_path(name: str, tables_dir: Path = SHIPPED_TABLES) -> Path:
    """A table by name (``<tables_dir>/<name>.yaml``) or a user's own table spec by path (``*.yaml``)."""
    if name.endswith((".yaml", ".yml")):
        own = Path(name)
        if not own.is_file():
            raise BenchInputError(own, "table spec file does not exist")
        return own
    path = Path(tables_dir) / f"{name}.yaml"
    if not path.exists():
        raise BenchInputError(path, f"no table {name!r} (known: {list_tables(tables_dir)})")
    return path


def load_tables(names: Sequence[str], tables_dir: Path = SHIPPED_TABLES) -> list[TableSpec]:
    """The specs of ``names`` (``["all"]``: every table in ``tables_dir``)."""
    if list(names) == ["all"]:
        names = list_tables(tables_dir)
    return [load_table_spec(table_path(n, tables_dir)) for n in names]


def plan_jobs(spec: TableSpec, scale: str) -> list[JobPlan]:
    """Every job the table expects at ``scale``: measured rows x groups x scenes x seeds.

    The job's overrides are the group's overrides updated by the row's (the row wins on a clash).
    """
    res = resolve(spec, scale)
    jobs: list[JobPlan] = []
    for row in spec.rows:
        assert row.method is not None
        for g in spec.groups:
            overrides = {**g.overrides, **row.overrides}
            for scene in res.scenes[g.id]:
                for seed in res.seeds:
                    jobs.append(JobPlan(spec.name, row.label, row.method, overrides, g.id, g.dataset,
                                        g.protocol, scene, seed, scale, g.effects))
    return jobs


def select_plans(spec: TableSpec, plans: list[JobPlan], rows: Sequence[str] | None, scenes: Sequence[str] | None,
                 seeds: Sequence[int] | None) -> list[JobPlan]:
    """Restrict a table's job plans to some row labels / scenes, or replace its seeds (CLI filters)."""
    if rows:
        unknown = set(rows) - {r.label for r in spec.rows}
        if unknown:
            raise BenchInputError(spec.path or spec.name, f"no row(s) {sorted(unknown)} (rows: {[r.label for r in spec.rows]})")
        plans = [p for p in plans if p.row in rows]
    if scenes:
        unknown = set(scenes) - {p.scene for p in plans}
        if unknown:
            raise BenchInputError(spec.path or spec.name, f"no scene(s) {sorted(unknown)} in this table "
                                  f"(scenes: {sorted({p.scene for p in plans})})")
        plans = [p for p in plans if p.scene in scenes]
    if seeds:
        plans = [replace(p, seed=s) for p in {(p.row, p.group, p.scene): p for p in plans}.values() for s in seeds]
    return plans


@dataclass(frozen=True)
class PlannedTable:
    """One table's jobs at a scale: ``jobs`` runnable, ``pending`` plans whose method is not implemented."""

    spec: TableSpec
    jobs: list[Job]
    pending: list[JobPlan]


def plan_table(spec: TableSpec, scale: str, rows: Sequence[str] | None = None, scenes: Sequence[str] | None = None,
               seeds: Sequence[int] | None = None, threads: int | None = None) -> PlannedTable:
    """Plan, filter and resolve one table's jobs (``threads``: see :func:`bench.runner.job_id_for`)."""
    jobs, pending = resolve_jobs(select_plans(spec, plan_jobs(spec, scale), rows, scenes, seeds), threads)
    return PlannedTable(spec, jobs, pending)
