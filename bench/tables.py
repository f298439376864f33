"""Table specs: which rows (method variants), scenes, seeds and metric columns make up one of the
paper's tables, the paper's published values, and the paper's claims to check.

A spec is a YAML file in ``configs/tables/``; :func:`load_table_spec` parses it strictly (unknown keys,
unknown directions, claims naming rows or metrics that do not exist, scales missing from a group all
raise :class:`~bench.data.errors.BenchInputError` naming the file and the key). The schema::

    name: ablation                      # must equal the file stem
    title: "Table 4: ..."
    paper_table: "Table 4"
    notes: ["free text shown under the table"]          # optional
    main_metric: fscore                 # optional: headline metric (plot y axis); default: the
                                        # first measured "higher" column
    datasets:                           # column groups, in display order
      - id: scannet                     # optional, defaults to `dataset`; unique in the table
        label: ScanNet                  # optional, header prefix; defaults to id
        dataset: scannet                # scannet | replica | dtu | llff
        protocol: scannet               # mesh/image evaluation protocol the runner uses
        scenes: {tiny: [scannet_like_tiny], small: [scannet_like_0, scannet_like_1]}
        overrides: {}                   # optional, merged into every row's method-config overrides
        effects: {prior_profile: {profile: sim-geowizard}}   # optional scene variant: the group's scenes
                                        # are made with these effect parameters (e.g. another prior)
        columns:
          - {key: acc, label: Acc, direction: lower, unit: m, fmt: ".3f"}
          - {key: lpips, label: LPIPS, direction: lower, paper_only: true}   # never measured by us
          - {key: cd, label: CD, direction: lower, unit: m, paper_unit: mm}  # paper values in another unit
        extra_metrics: [unc_mean_thin]  # optional: metrics not shown as columns but usable by claims
    seeds: {tiny: [0], small: [0, 1, 2]}
    rows:
      - label: Base
        method: monoinstance            # a name in the method registry
        overrides: {uncertainty: false} # config overrides: variants are configs, not copies
        paper: {scannet: {acc: 0.039}}  # or null; keyed by group id then column key; null value = "-"
        paper_label: null               # optional: the paper's row name when it differs from `label`
    paper_only_rows:
      - {label: MonoSDF, paper: {scannet: {acc: 0.035}}}
    anchors: {object_mode: &object_mode {...}}  # optional, ignored: YAML anchors reused by rows
    convergence:                        # optional: when a trained row counts as a result (bench.convergence)
      {metric: fscore, flat: 0.03, drop: 0.05, seed_std: 0.03}   # flat / drop / seed_std optional (these defaults)
    claims:
      - {id: c1, text: "...", kind: monotone, group: scannet, metric: fscore,
         rows: [A, B, C], direction: increasing, strict: true}
      - {id: c2, text: "...", kind: greater, group: scannet, row: A, metric_a: m1, metric_b: m2}
      - {id: c3, text: "...", kind: better, group: [g1, g2], row_a: A, row_b: B, metric: fscore}

``group`` of a claim is one group id or a list of them (the claim must hold in each). ``better``
takes its direction from the column (or from an explicit ``direction: higher|lower`` for extra
metrics). With ``convergence``, every trained row is judged by those criteria, and a claim that
compares a row that has not converged is UNDECIDED (its comparison on the measured numbers is still shown).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, Mapping

import yaml

from bench.convergence import ConvergenceSpec
from bench.data.errors import BenchInputError
from bench.jobs import JobPlan
from bench.data.scene import DATASET_FORMATS

Direction = Literal["lower", "higher"]
ClaimKind = Literal["monotone", "greater", "better"]
DIRECTIONS: tuple[str, ...] = ("lower", "higher")
TREND_DIRECTIONS: tuple[str, ...] = ("increasing", "decreasing")
CLAIM_KINDS: tuple[str, ...] = ("monotone", "greater", "better")
PROTOCOLS: tuple[str, ...] = DATASET_FORMATS
_NAME_RE = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.-]*$")


@dataclass(frozen=True)
class Column:
    """One metric column: ``key`` in the result rows' ``metrics``, shown as ``label``."""

    key: str
    label: str
    direction: Direction
    unit: str = ""
    fmt: str = ".3f"
    paper_only: bool = False
    paper_unit: str | None = None

    @property
    def published_unit(self) -> str:
        """Unit of the paper's values in this column (``paper_unit`` if given, else ``unit``)."""
        return self.unit if self.paper_unit is None else self.paper_unit

    @property
    def arrow(self) -> str:
        """``"↓"`` when lower is better, ``"↑"`` when higher is better."""
        return "↓" if self.direction == "lower" else "↑"


@dataclass(frozen=True)
class DatasetGroup:
    """A column group: one dataset (optionally with method-config overrides and a scene variant)."""

    id: str
    label: str
    dataset: str
    protocol: str
    scenes: Mapping[str, tuple[str, ...]]
    columns: tuple[Column, ...]
    overrides: Mapping[str, Any] = field(default_factory=dict)
    effects: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    extra_metrics: tuple[str, ...] = ()

    def column(self, key: str) -> Column | None:
        """The column named ``key``, or None."""
        return next((c for c in self.columns if c.key == key), None)

    def has_metric(self, key: str) -> bool:
        """True if ``key`` is a column or an extra metric of this group."""
        return self.column(key) is not None or key in self.extra_metrics


@dataclass(frozen=True)
class RowSpec:
    """A table row. ``method`` is None for a paper-only row (another published method)."""

    label: str
    method: str | None
    overrides: Mapping[str, Any] = field(default_factory=dict)
    paper: Mapping[str, Mapping[str, float | None]] | None = None
    paper_label: str | None = None

    @property
    def paper_only(self) -> bool:
        """True for rows that exist only as published values."""
        return self.method is None


@dataclass(frozen=True)
class ClaimSpec:
    """A claim of the paper, checked on our results (and, where available, on the paper's values)."""

    id: str
    text: str
    kind: ClaimKind
    groups: tuple[str, ...]
    rows: tuple[str, ...]
    metric: str | None = None
    direction: str | None = None
    strict: bool = True
    metric_a: str | None = None
    metric_b: str | None = None
    margin: float = 0.0  # "better" claims: row_a must beat row_b by more than this (metric units)


@dataclass(frozen=True)
class TableSpec:
    """A parsed, validated table spec (see the module docstring for the YAML schema)."""

    name: str
    title: str
    paper_table: str
    groups: tuple[DatasetGroup, ...]
    seeds: Mapping[str, tuple[int, ...]]
    rows: tuple[RowSpec, ...]
    paper_only_rows: tuple[RowSpec, ...] = ()
    claims: tuple[ClaimSpec, ...] = ()
    notes: tuple[str, ...] = ()
    main_metric_key: str | None = None
    path: str = ""
    convergence: ConvergenceSpec | None = None

    @property
    def scales(self) -> tuple[str, ...]:
        """Scales this table defines (the keys of ``seeds``)."""
        return tuple(self.seeds)

    def group(self, gid: str) -> DatasetGroup:
        """The group with id ``gid`` (KeyError if absent)."""
        for g in self.groups:
            if g.id == gid:
                return g
        raise KeyError(gid)

    def row(self, label: str) -> RowSpec:
        """The measured row labelled ``label`` (KeyError if absent)."""
        for r in self.rows:
            if r.label == label:
                return r
        raise KeyError(label)

    def main_metric(self) -> tuple[DatasetGroup, Column]:
        """The table's headline metric: ``main_metric`` if given, else the first measured "higher"
        column (else the first measured column); returned with the first group that has it."""
        measured = [(g, c) for g in self.groups for c in g.columns if not c.paper_only]
        if self.main_metric_key is not None:
            return next((g, c) for g, c in measured if c.key == self.main_metric_key)
        for g, c in measured:
            if c.direction == "higher":
                return g, c
        return measured[0]


@dataclass(frozen=True)
class Resolved:
    """Scenes per group and seeds of a table at one scale."""

    scale: str
    scenes: Mapping[str, tuple[str, ...]]
    seeds: tuple[int, ...]

    def n_expected(self, group: str) -> int:
        """Number of jobs one row expects in ``group`` (scenes x seeds)."""
        return len(self.scenes[group]) * len(self.seeds)


# --------------------------------------------------------------------------------------------------
# parsing helpers


class _Ctx:
    """Carries the file name so every error names it and the offending key path."""

    def __init__(self, path: str | Path) -> None:
        self.path = str(path)

    def fail(self, key: str, problem: str) -> BenchInputError:
        return BenchInputError(self.path, f"{key}: {problem}" if key else problem)

    def mapping(self, obj: Any, key: str, required: set[str], optional: set[str]) -> dict[str, Any]:
        if not isinstance(obj, dict):
            raise self.fail(key, f"expected a mapping, got {type(obj).__name__}")
        unknown = sorted(set(map(str, obj)) - required - optional)
        if unknown:
            allowed = ", ".join(sorted(required | optional))
            raise self.fail(key, f"unknown key(s) {unknown} (allowed: {allowed})")
        missing = sorted(required - set(obj))
        if missing:
            raise self.fail(key, f"missing key(s) {missing}")
        return obj

    def string(self, obj: Any, key: str, pattern: bool = False) -> str:
        if not isinstance(obj, str) or not obj.strip():
            raise self.fail(key, f"expected a non-empty string, got {obj!r}")
        if pattern and not _NAME_RE.match(obj):
            raise self.fail(key, f"{obj!r} is not a valid name (letters, digits, _ . -)")
        return obj

    def strlist(self, obj: Any, key: str) -> tuple[str, ...]:
        if not isinstance(obj, list) or not obj:
            raise self.fail(key, f"expected a non-empty list, got {obj!r}")
        return tuple(self.string(x, f"{key}[{i}]") for i, x in enumerate(obj))

    def choice(self, obj: Any, key: str, choices: tuple[str, ...]) -> str:
        if obj not in choices:
            raise self.fail(key, f"unknown value {obj!r} (expected one of {list(choices)})")
        return str(obj)

    def boolean(self, obj: Any, key: str) -> bool:
        if not isinstance(obj, bool):
            raise self.fail(key, f"expected true/false, got {obj!r}")
        return obj

    def per_scale(self, obj: Any, key: str, item: str) -> dict[str, tuple[Any, ...]]:
        if not isinstance(obj, dict) or not obj:
            raise self.fail(key, f"expected a mapping scale -> list of {item}, got {obj!r}")
        out: dict[str, tuple[Any, ...]] = {}
        for scale, values in obj.items():
            k = f"{key}.{scale}"
            self.string(scale, k, pattern=True)
            if item == "seeds":
                if not isinstance(values, list) or not values:
                    raise self.fail(k, f"expected a non-empty list of integer seeds, got {values!r}")
                if not all(isinstance(s, int) and not isinstance(s, bool) for s in values):
                    raise self.fail(k, f"seeds must be integers, got {values!r}")
                out[scale] = tuple(values)
            else:
                out[scale] = self.strlist(values, k)
            if len(set(out[scale])) != len(out[scale]):
                raise self.fail(k, f"duplicate {item} in {values!r}")
        return out


def _column(ctx: _Ctx, obj: Any, key: str) -> Column:
    d = ctx.mapping(obj, key, {"key", "label", "direction"}, {"unit", "fmt", "paper_only", "paper_unit"})
    fmt = d.get("fmt", ".3f")
    try:
        format(1.0, ctx.string(fmt, f"{key}.fmt"))
    except ValueError as e:
        raise ctx.fail(f"{key}.fmt", f"bad format {fmt!r}: {e}") from None
    unit = d.get("unit", "")
    if unit is None or not isinstance(unit, str):
        raise ctx.fail(f"{key}.unit", f"expected a string (may be empty), got {unit!r}")
    return Column(
        key=ctx.string(d["key"], f"{key}.key", pattern=True),
        label=ctx.string(d["label"], f"{key}.label"),
        direction=ctx.choice(d["direction"], f"{key}.direction", DIRECTIONS),  # type: ignore[arg-type]
        unit=unit,
        fmt=fmt,
        paper_only=ctx.boolean(d.get("paper_only", False), f"{key}.paper_only"),
        paper_unit=None if d.get("paper_unit") is None else ctx.string(d["paper_unit"], f"{key}.paper_unit"),
    )


def _group(ctx: _Ctx, obj: Any, key: str) -> DatasetGroup:
    d = ctx.mapping(
        obj, key, {"dataset", "protocol", "scenes", "columns"}, {"id", "label", "overrides", "effects", "extra_metrics"}
    )
    dataset = ctx.choice(d["dataset"], f"{key}.dataset", DATASET_FORMATS)
    gid = ctx.string(d.get("id", dataset), f"{key}.id", pattern=True)
    cols_obj = d["columns"]
    if not isinstance(cols_obj, list) or not cols_obj:
        raise ctx.fail(f"{key}.columns", "expected a non-empty list of columns")
    columns = tuple(_column(ctx, c, f"{key}.columns[{i}]") for i, c in enumerate(cols_obj))
    keys = [c.key for c in columns]
    if len(set(keys)) != len(keys):
        raise ctx.fail(f"{key}.columns", f"duplicate column keys in {keys}")
    if all(c.paper_only for c in columns):
        raise ctx.fail(f"{key}.columns", "every column is paper_only: nothing to measure")
    overrides = d.get("overrides", {})
    if not isinstance(overrides, dict):
        raise ctx.fail(f"{key}.overrides", f"expected a mapping, got {overrides!r}")
    effects = d.get("effects", {}) or {}
    if not isinstance(effects, dict) or not all(isinstance(v, dict) for v in effects.values()):
        raise ctx.fail(f"{key}.effects", f"expected {{effect name: {{parameter: value}}}}, got {effects!r}")
    extra = d.get("extra_metrics", [])
    extra_t = ctx.strlist(extra, f"{key}.extra_metrics") if extra else ()
    if set(extra_t) & set(keys):
        raise ctx.fail(f"{key}.extra_metrics", f"{sorted(set(extra_t) & set(keys))} are already columns")
    return DatasetGroup(
        id=gid,
        label=ctx.string(d.get("label", gid), f"{key}.label"),
        dataset=dataset,
        protocol=ctx.choice(d["protocol"], f"{key}.protocol", PROTOCOLS),
        scenes=ctx.per_scale(d["scenes"], f"{key}.scenes", "scenes"),
        columns=columns,
        overrides=dict(overrides),
        effects={k: dict(v) for k, v in effects.items()},
        extra_metrics=extra_t,
    )


def _paper(ctx: _Ctx, obj: Any, key: str, groups: tuple[DatasetGroup, ...]) -> dict[str, dict[str, float | None]] | None:
    if obj is None:
        return None
    if not isinstance(obj, dict):
        raise ctx.fail(key, f"expected a mapping group -> {{metric: value}} or null, got {obj!r}")
    by_id = {g.id: g for g in groups}
    out: dict[str, dict[str, float | None]] = {}
    for gid, vals in obj.items():
        k = f"{key}.{gid}"
        if gid not in by_id:
            raise ctx.fail(k, f"unknown group {gid!r} (groups: {sorted(by_id)})")
        if not isinstance(vals, dict):
            raise ctx.fail(k, f"expected a mapping metric -> value, got {vals!r}")
        out[gid] = {}
        for m, v in vals.items():
            if by_id[gid].column(m) is None:
                raise ctx.fail(f"{k}.{m}", f"unknown column (columns: {[c.key for c in by_id[gid].columns]})")
            if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float))):
                raise ctx.fail(f"{k}.{m}", f"expected a number or null, got {v!r}")
            out[gid][m] = None if v is None else float(v)
    return out


def _row(ctx: _Ctx, obj: Any, key: str, groups: tuple[DatasetGroup, ...], paper_only: bool) -> RowSpec:
    if paper_only:
        d = ctx.mapping(obj, key, {"label", "paper"}, set())
        paper = _paper(ctx, d["paper"], f"{key}.paper", groups)
        if not paper:
            raise ctx.fail(f"{key}.paper", "a paper-only row needs paper values")
        return RowSpec(label=ctx.string(d["label"], f"{key}.label"), method=None, paper=paper)
    d = ctx.mapping(obj, key, {"label", "method"}, {"overrides", "paper", "paper_label"})
    overrides = d.get("overrides", {}) or {}
    if not isinstance(overrides, dict):
        raise ctx.fail(f"{key}.overrides", f"expected a mapping, got {overrides!r}")
    paper_label = d.get("paper_label")
    return RowSpec(
        label=ctx.string(d["label"], f"{key}.label"),
        method=ctx.string(d["method"], f"{key}.method", pattern=True),
        overrides=dict(overrides),
        paper=_paper(ctx, d.get("paper"), f"{key}.paper", groups),
        paper_label=None if paper_label is None else ctx.string(paper_label, f"{key}.paper_label"),
    )


def _claim(ctx: _Ctx, obj: Any, key: str, groups: tuple[DatasetGroup, ...], rows: tuple[RowSpec, ...]) -> ClaimSpec:
    common = {"id", "text", "kind", "group"}
    if not isinstance(obj, dict):
        raise ctx.fail(key, f"expected a mapping, got {type(obj).__name__}")
    kind = ctx.choice(obj.get("kind"), f"{key}.kind", CLAIM_KINDS)
    if kind == "monotone":
        d = ctx.mapping(obj, key, common | {"metric", "rows", "direction"}, {"strict"})
        row_names = ctx.strlist(d["rows"], f"{key}.rows")
        if len(row_names) < 2:
            raise ctx.fail(f"{key}.rows", "a monotone claim needs at least two rows")
        direction = ctx.choice(d["direction"], f"{key}.direction", TREND_DIRECTIONS)
    elif kind == "greater":
        d = ctx.mapping(obj, key, common | {"metric_a", "metric_b"}, {"row", "rows"})
        if ("row" in d) == ("rows" in d):
            raise ctx.fail(key, "a greater claim needs exactly one of `row` or `rows`")
        row_names = (ctx.string(d["row"], f"{key}.row"),) if "row" in d else ctx.strlist(d["rows"], f"{key}.rows")
        direction = None
    else:
        d = ctx.mapping(obj, key, common | {"metric", "row_a", "row_b"}, {"direction", "margin"})
        row_names = (ctx.string(d["row_a"], f"{key}.row_a"), ctx.string(d["row_b"], f"{key}.row_b"))
        direction = ctx.choice(d["direction"], f"{key}.direction", DIRECTIONS) if "direction" in d else None
    g = d["group"]
    gids = (ctx.string(g, f"{key}.group"),) if isinstance(g, str) else ctx.strlist(g, f"{key}.group")
    by_id = {x.id: x for x in groups}
    for gid in gids:
        if gid not in by_id:
            raise ctx.fail(f"{key}.group", f"unknown group {gid!r} (groups: {sorted(by_id)})")
    labels = {r.label for r in rows}
    for r in row_names:
        if r not in labels:
            raise ctx.fail(key, f"unknown row {r!r} (measured rows: {sorted(labels)})")
    metrics = [d["metric"]] if kind != "greater" else [d["metric_a"], d["metric_b"]]
    for m in metrics:
        ctx.string(m, f"{key}.metric")
        for gid in gids:
            grp = by_id[gid]
            if not grp.has_metric(m):
                raise ctx.fail(f"{key}.metric", f"unknown metric {m!r} in group {gid!r} (columns and extra_metrics: "
                               f"{[c.key for c in grp.columns] + list(grp.extra_metrics)})")
            col = grp.column(m)
            if col is not None and col.paper_only:
                raise ctx.fail(f"{key}.metric", f"{m!r} is paper_only in group {gid!r}: we never measure it")
            if kind == "better" and col is None and direction is None:
                raise ctx.fail(f"{key}.direction", f"{m!r} is not a column: give direction: higher|lower")
    return ClaimSpec(
        id=ctx.string(d["id"], f"{key}.id", pattern=True),
        text=ctx.string(d["text"], f"{key}.text"),
        kind=kind,  # type: ignore[arg-type]
        groups=gids,
        rows=row_names,
        metric=d.get("metric"),
        direction=direction,
        strict=ctx.boolean(d.get("strict", True), f"{key}.strict"),
        metric_a=d.get("metric_a"),
        metric_b=d.get("metric_b"),
        margin=_margin(ctx, d.get("margin", 0.0), f"{key}.margin"),
    )


def _margin(ctx: _Ctx, value: Any, key: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(float(value)) or value < 0:
        raise ctx.fail(key, f"expected a number >= 0, got {value!r}")
    return float(value)


def _convergence(ctx: _Ctx, obj: Any, key: str, groups: tuple[DatasetGroup, ...]) -> ConvergenceSpec:
    d = ctx.mapping(obj, key, {"metric"}, {"flat", "drop", "seed_std"})
    metric = ctx.string(d["metric"], f"{key}.metric")
    col = next((c for g in groups for c in g.columns if c.key == metric and not c.paper_only), None)
    if col is None:
        raise ctx.fail(f"{key}.metric", f"{metric!r} is not a measured column of any group")
    tol = {k: _margin(ctx, d[k], f"{key}.{k}") for k in ("flat", "drop", "seed_std") if k in d}
    return ConvergenceSpec(metric=metric, higher_is_better=col.direction == "higher", **tol)


# --------------------------------------------------------------------------------------------------
# public API


def parse_table_spec(obj: Any, where: str | Path = "<table spec>") -> TableSpec:
    """Validate an already-loaded YAML mapping; errors name ``where`` and the key path."""
    ctx = _Ctx(where)
    d = ctx.mapping(
        obj, "", {"name", "title", "datasets", "seeds", "rows"},
        {"paper_table", "paper_only_rows", "claims", "notes", "main_metric", "anchors", "convergence"},
    )
    name = ctx.string(d["name"], "name", pattern=True)
    if isinstance(where, Path) and where.suffix in (".yaml", ".yml") and where.stem != name:
        raise ctx.fail("name", f"{name!r} differs from the file name {where.stem!r}")
    if not isinstance(d["datasets"], list) or not d["datasets"]:
        raise ctx.fail("datasets", "expected a non-empty list of column groups")
    groups = tuple(_group(ctx, g, f"datasets[{i}]") for i, g in enumerate(d["datasets"]))
    ids = [g.id for g in groups]
    if len(set(ids)) != len(ids):
        raise ctx.fail("datasets", f"duplicate group ids {ids}: give each group a distinct `id`")
    seeds = ctx.per_scale(d["seeds"], "seeds", "seeds")
    for g, i in zip(groups, range(len(groups))):
        missing = sorted(set(seeds) - set(g.scenes))
        if missing:
            raise ctx.fail(f"datasets[{i}].scenes", f"missing scale(s) {missing} (seeds define {sorted(seeds)})")
        extra = sorted(set(g.scenes) - set(seeds))
        if extra:
            raise ctx.fail("seeds", f"missing scale(s) {extra} used by datasets[{i}].scenes")
    if not isinstance(d["rows"], list) or not d["rows"]:
        raise ctx.fail("rows", "expected a non-empty list of rows")
    rows = tuple(_row(ctx, r, f"rows[{i}]", groups, False) for i, r in enumerate(d["rows"]))
    pobj = d.get("paper_only_rows") or []
    if not isinstance(pobj, list):
        raise ctx.fail("paper_only_rows", "expected a list")
    prows = tuple(_row(ctx, r, f"paper_only_rows[{i}]", groups, True) for i, r in enumerate(pobj))
    labels = [r.label for r in rows + prows]
    dup = sorted({x for x in labels if labels.count(x) > 1})
    if dup:
        raise ctx.fail("rows", f"duplicate row label(s) {dup}")
    cobj = d.get("claims") or []
    if not isinstance(cobj, list):
        raise ctx.fail("claims", "expected a list")
    claims = tuple(_claim(ctx, c, f"claims[{i}]", groups, rows) for i, c in enumerate(cobj))
    cids = [c.id for c in claims]
    if len(set(cids)) != len(cids):
        raise ctx.fail("claims", f"duplicate claim ids {cids}")
    notes = d.get("notes") or []
    main = d.get("main_metric")
    if main is not None:
        ctx.string(main, "main_metric")
        if not any(c.key == main and not c.paper_only for g in groups for c in g.columns):
            raise ctx.fail("main_metric", f"{main!r} is not a measured column of any group")
    convergence = _convergence(ctx, d["convergence"], "convergence", groups) if d.get("convergence") is not None else None
    return TableSpec(
        name=name,
        title=ctx.string(d["title"], "title"),
        paper_table=ctx.string(d["paper_table"], "paper_table") if "paper_table" in d else "",  # a user's own table may have none
        groups=groups,
        seeds=seeds,
        rows=rows,
        paper_only_rows=prows,
        claims=claims,
        notes=ctx.strlist(notes, "notes") if notes else (),
        main_metric_key=main,
        path=str(where),
        convergence=convergence,
    )


def load_table_spec(path: str | Path) -> TableSpec:
    """Read and validate one table spec YAML file (BenchInputError naming the file and key if bad)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as e:
        raise BenchInputError(path, f"cannot read table spec: {e.strerror or e}") from None
    try:
        obj = yaml.safe_load(text)
    except yaml.YAMLError as e:
        raise BenchInputError(path, f"not valid YAML: {e}") from None
    return parse_table_spec(obj, path)


def list_tables(configs_dir: str | Path) -> list[str]:
    """Names of the table specs in ``configs_dir`` (or in ``configs_dir/tables`` if that exists), sorted."""
    d = Path(configs_dir)
    if (d / "tables").is_dir():
        d = d / "tables"
    if not d.is_dir():
        raise BenchInputError(d, "no such folder of table specs")
    return sorted(p.stem for p in d.glob("*.yaml") if not p.name.startswith("."))


def resolve(spec: TableSpec, scale: str) -> Resolved:
    """Scenes per group and seeds of ``spec`` at ``scale`` (BenchInputError if the scale is missing)."""
    if scale not in spec.seeds:
        raise BenchInputError(spec.path or spec.name, f"seeds: no scale {scale!r} (defined: {list(spec.seeds)})")
    return Resolved(scale=scale, scenes={g.id: tuple(g.scenes[scale]) for g in spec.groups}, seeds=tuple(spec.seeds[scale]))


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
