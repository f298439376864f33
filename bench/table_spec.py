"""Table specs: which rows (method variants), scenes, seeds and metric columns make up one of the
paper's tables, the paper's published values, and the paper's claims to check.

A spec is a YAML file in ``configs/tables/``; :func:`load_table_spec` parses it strictly: its records
(the table, groups, columns, rows, the three claim kinds, convergence criteria) are typed dataclasses
filled by :func:`bench.data.config.load_config` (unknown keys, missing keys, wrong types), then the
references between them are checked (claims naming rows or metrics that do not exist, scales missing
from a group); every problem raises :class:`~bench.data.errors.BenchInputError` naming the file and the
key path. The jobs a spec
expects are planned by :func:`bench.pipeline.plan_jobs`. The schema::

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

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, Literal, Mapping

import yaml

from bench.convergence import ConvergenceSpec
from bench.data.config import Range, load_config
from bench.data.errors import BenchInputError
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


# --------------------------------------------------------------------------------------------------
# the YAML's records, typed (bench.data.config: unknown keys, missing keys and wrong types are errors
# naming the file and the key path); the checks between records (names, references) follow in code

NonNegative = Annotated[float, Range(lo=0)]
PaperValues = dict[str, dict[str, float | None]]  # group id -> column key -> value (null = "-")


@dataclass(frozen=True)
class _GroupRecord:
    dataset: str
    protocol: str
    scenes: dict[str, Any]
    columns: tuple[Column, ...]
    id: str | None = None
    label: str | None = None
    overrides: dict[str, Any] = field(default_factory=dict)
    effects: dict[str, dict[str, Any]] = field(default_factory=dict)
    extra_metrics: tuple[str, ...] = ()


@dataclass(frozen=True)
class _RowRecord:
    label: str
    method: str
    overrides: dict[str, Any] = field(default_factory=dict)
    paper: PaperValues | None = None
    paper_label: str | None = None


@dataclass(frozen=True)
class _PaperRowRecord:
    label: str
    paper: PaperValues


@dataclass(frozen=True)
class _Claim:
    """The keys every claim kind has (``kind`` picks the record: monotone / greater / better)."""

    id: str
    text: str
    group: str | tuple[str, ...]


@dataclass(frozen=True)
class _MonotoneClaim(_Claim):
    kind: Literal["monotone"]
    metric: str
    rows: tuple[str, ...]
    direction: Literal["increasing", "decreasing"]
    strict: bool = True


@dataclass(frozen=True)
class _GreaterClaim(_Claim):
    kind: Literal["greater"]
    metric_a: str
    metric_b: str
    row: str | None = None
    rows: tuple[str, ...] | None = None


@dataclass(frozen=True)
class _BetterClaim(_Claim):
    kind: Literal["better"]
    metric: str
    row_a: str
    row_b: str
    direction: Direction | None = None
    margin: NonNegative = 0.0


_CLAIM_RECORDS: dict[str, type] = {"monotone": _MonotoneClaim, "greater": _GreaterClaim, "better": _BetterClaim}


@dataclass(frozen=True)
class _ConvergenceRecord:
    metric: str
    flat: NonNegative = ConvergenceSpec.flat  # the defaults are ConvergenceSpec's (one place)
    drop: NonNegative = ConvergenceSpec.drop
    seed_std: NonNegative = ConvergenceSpec.seed_std


@dataclass(frozen=True)
class _TableRecord:
    name: str
    title: str
    datasets: tuple[_GroupRecord, ...]
    seeds: dict[str, Any]
    rows: tuple[_RowRecord, ...]
    paper_table: str | None = None
    paper_only_rows: tuple[_PaperRowRecord, ...] | None = None
    claims: tuple[dict[str, Any], ...] | None = None
    notes: tuple[str, ...] | None = None
    main_metric: str | None = None
    anchors: Any = None
    convergence: _ConvergenceRecord | None = None


def _column(ctx: _Ctx, col: Column, key: str) -> Column:
    ctx.string(col.key, f"{key}.key", pattern=True)
    ctx.string(col.label, f"{key}.label")
    try:
        format(1.0, ctx.string(col.fmt, f"{key}.fmt"))
    except ValueError as e:
        raise ctx.fail(f"{key}.fmt", f"bad format {col.fmt!r}: {e}") from None
    if col.paper_unit is not None:
        ctx.string(col.paper_unit, f"{key}.paper_unit")
    return col


def _group(ctx: _Ctx, rec: _GroupRecord, key: str) -> DatasetGroup:
    dataset = ctx.choice(rec.dataset, f"{key}.dataset", DATASET_FORMATS)
    gid = ctx.string(rec.id if rec.id is not None else dataset, f"{key}.id", pattern=True)
    if not rec.columns:
        raise ctx.fail(f"{key}.columns", "expected a non-empty list of columns")
    columns = tuple(_column(ctx, c, f"{key}.columns[{i}]") for i, c in enumerate(rec.columns))
    keys = [c.key for c in columns]
    if len(set(keys)) != len(keys):
        raise ctx.fail(f"{key}.columns", f"duplicate column keys in {keys}")
    if all(c.paper_only for c in columns):
        raise ctx.fail(f"{key}.columns", "every column is paper_only: nothing to measure")
    extra_t = tuple(ctx.string(x, f"{key}.extra_metrics[{i}]") for i, x in enumerate(rec.extra_metrics))
    if set(extra_t) & set(keys):
        raise ctx.fail(f"{key}.extra_metrics", f"{sorted(set(extra_t) & set(keys))} are already columns")
    return DatasetGroup(
        id=gid,
        label=ctx.string(rec.label if rec.label is not None else gid, f"{key}.label"),
        dataset=dataset,
        protocol=ctx.choice(rec.protocol, f"{key}.protocol", PROTOCOLS),
        scenes=ctx.per_scale(rec.scenes, f"{key}.scenes", "scenes"),
        columns=columns,
        overrides=dict(rec.overrides),
        effects={k: dict(v) for k, v in rec.effects.items()},
        extra_metrics=extra_t,
    )


def _paper(ctx: _Ctx, values: PaperValues | None, key: str, groups: tuple[DatasetGroup, ...]) -> dict[str, dict[str, float | None]] | None:
    """Paper values checked against the groups' columns (their types are checked by the record)."""
    if values is None:
        return None
    by_id = {g.id: g for g in groups}
    for gid, vals in values.items():
        k = f"{key}.{gid}"
        if gid not in by_id:
            raise ctx.fail(k, f"unknown group {gid!r} (groups: {sorted(by_id)})")
        for m in vals:
            if by_id[gid].column(m) is None:
                raise ctx.fail(f"{k}.{m}", f"unknown column (columns: {[c.key for c in by_id[gid].columns]})")
    return {gid: dict(vals) for gid, vals in values.items()}


def _row(ctx: _Ctx, rec: _RowRecord, key: str, groups: tuple[DatasetGroup, ...]) -> RowSpec:
    return RowSpec(
        label=ctx.string(rec.label, f"{key}.label"),
        method=ctx.string(rec.method, f"{key}.method", pattern=True),
        overrides=dict(rec.overrides),
        paper=_paper(ctx, rec.paper, f"{key}.paper", groups),
        paper_label=None if rec.paper_label is None else ctx.string(rec.paper_label, f"{key}.paper_label"),
    )


def _paper_row(ctx: _Ctx, rec: _PaperRowRecord, key: str, groups: tuple[DatasetGroup, ...]) -> RowSpec:
    paper = _paper(ctx, rec.paper, f"{key}.paper", groups)
    if not paper:
        raise ctx.fail(f"{key}.paper", "a paper-only row needs paper values")
    return RowSpec(label=ctx.string(rec.label, f"{key}.label"), method=None, paper=paper)


def _claim(ctx: _Ctx, obj: Any, key: str, groups: tuple[DatasetGroup, ...], rows: tuple[RowSpec, ...]) -> ClaimSpec:
    if not isinstance(obj, dict):
        raise ctx.fail(key, f"expected a mapping, got {type(obj).__name__}")
    kind = ctx.choice(obj.get("kind"), f"{key}.kind", CLAIM_KINDS)
    rec: _MonotoneClaim | _GreaterClaim | _BetterClaim = load_config(_CLAIM_RECORDS[kind], obj, ctx.path, key=key)
    direction: str | None = None
    if isinstance(rec, _MonotoneClaim):
        row_names = tuple(ctx.string(r, f"{key}.rows[{i}]") for i, r in enumerate(rec.rows))
        if len(row_names) < 2:
            raise ctx.fail(f"{key}.rows", "a monotone claim needs at least two rows")
        direction = rec.direction
        metrics = [rec.metric]
    elif isinstance(rec, _GreaterClaim):
        if (rec.row is None) == (rec.rows is None):
            raise ctx.fail(key, "a greater claim needs exactly one of `row` or `rows`")
        row_names = (ctx.string(rec.row, f"{key}.row"),) if rec.row is not None else \
            tuple(ctx.string(r, f"{key}.rows[{i}]") for i, r in enumerate(rec.rows or ()))
        if not row_names:
            raise ctx.fail(f"{key}.rows", "expected a non-empty list")
        metrics = [rec.metric_a, rec.metric_b]
    else:
        row_names = (ctx.string(rec.row_a, f"{key}.row_a"), ctx.string(rec.row_b, f"{key}.row_b"))
        direction = rec.direction
        metrics = [rec.metric]
    gids = (rec.group,) if isinstance(rec.group, str) else rec.group
    if not gids:
        raise ctx.fail(f"{key}.group", "expected a group id or a non-empty list of them")
    by_id = {x.id: x for x in groups}
    for gid in gids:
        if gid not in by_id:
            raise ctx.fail(f"{key}.group", f"unknown group {gid!r} (groups: {sorted(by_id)})")
    labels = {r.label for r in rows}
    for r in row_names:
        if r not in labels:
            raise ctx.fail(key, f"unknown row {r!r} (measured rows: {sorted(labels)})")
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
            if isinstance(rec, _BetterClaim) and col is None and direction is None:
                raise ctx.fail(f"{key}.direction", f"{m!r} is not a column: give direction: higher|lower")
    return ClaimSpec(
        id=ctx.string(rec.id, f"{key}.id", pattern=True),
        text=ctx.string(rec.text, f"{key}.text"),
        kind=kind,  # type: ignore[arg-type]
        groups=tuple(gids),
        rows=row_names,
        metric=None if isinstance(rec, _GreaterClaim) else rec.metric,
        direction=direction,
        strict=rec.strict if isinstance(rec, _MonotoneClaim) else True,
        metric_a=rec.metric_a if isinstance(rec, _GreaterClaim) else None,
        metric_b=rec.metric_b if isinstance(rec, _GreaterClaim) else None,
        margin=rec.margin if isinstance(rec, _BetterClaim) else 0.0,
    )


def _convergence(ctx: _Ctx, rec: _ConvergenceRecord, key: str, groups: tuple[DatasetGroup, ...]) -> ConvergenceSpec:
    metric = ctx.string(rec.metric, f"{key}.metric")
    col = next((c for g in groups for c in g.columns if c.key == metric and not c.paper_only), None)
    if col is None:
        raise ctx.fail(f"{key}.metric", f"{metric!r} is not a measured column of any group")
    return ConvergenceSpec(metric=metric, flat=rec.flat, drop=rec.drop, seed_std=rec.seed_std,
                           higher_is_better=col.direction == "higher")


# --------------------------------------------------------------------------------------------------
# public API


def parse_table_spec(obj: Any, where: str | Path = "<table spec>") -> TableSpec:
    """Validate an already-loaded YAML mapping; errors name ``where`` and the key path."""
    ctx = _Ctx(where)
    if not isinstance(obj, dict):
        raise ctx.fail("", f"expected a mapping, got {type(obj).__name__}")
    d = load_config(_TableRecord, obj, ctx.path)
    name = ctx.string(d.name, "name", pattern=True)
    if isinstance(where, Path) and where.suffix in (".yaml", ".yml") and where.stem != name:
        raise ctx.fail("name", f"{name!r} differs from the file name {where.stem!r}")
    if not d.datasets:
        raise ctx.fail("datasets", "expected a non-empty list of column groups")
    groups = tuple(_group(ctx, g, f"datasets[{i}]") for i, g in enumerate(d.datasets))
    ids = [g.id for g in groups]
    if len(set(ids)) != len(ids):
        raise ctx.fail("datasets", f"duplicate group ids {ids}: give each group a distinct `id`")
    seeds = ctx.per_scale(d.seeds, "seeds", "seeds")
    for i, g in enumerate(groups):
        missing = sorted(set(seeds) - set(g.scenes))
        if missing:
            raise ctx.fail(f"datasets[{i}].scenes", f"missing scale(s) {missing} (seeds define {sorted(seeds)})")
        extra = sorted(set(g.scenes) - set(seeds))
        if extra:
            raise ctx.fail("seeds", f"missing scale(s) {extra} used by datasets[{i}].scenes")
    if not d.rows:
        raise ctx.fail("rows", "expected a non-empty list of rows")
    rows = tuple(_row(ctx, r, f"rows[{i}]", groups) for i, r in enumerate(d.rows))
    prows = tuple(_paper_row(ctx, r, f"paper_only_rows[{i}]", groups) for i, r in enumerate(d.paper_only_rows or ()))
    labels = [r.label for r in rows + prows]
    dup = sorted({x for x in labels if labels.count(x) > 1})
    if dup:
        raise ctx.fail("rows", f"duplicate row label(s) {dup}")
    claims = tuple(_claim(ctx, c, f"claims[{i}]", groups, rows) for i, c in enumerate(d.claims or ()))
    cids = [c.id for c in claims]
    if len(set(cids)) != len(cids):
        raise ctx.fail("claims", f"duplicate claim ids {cids}")
    main = d.main_metric
    if main is not None:
        ctx.string(main, "main_metric")
        if not any(c.key == main and not c.paper_only for g in groups for c in g.columns):
            raise ctx.fail("main_metric", f"{main!r} is not a measured column of any group")
    return TableSpec(
        name=name,
        title=ctx.string(d.title, "title"),
        paper_table=ctx.string(d.paper_table, "paper_table") if d.paper_table is not None else "",  # a user's own table may have none
        groups=groups,
        seeds=seeds,
        rows=rows,
        paper_only_rows=prows,
        claims=claims,
        notes=tuple(ctx.string(n, f"notes[{i}]") for i, n in enumerate(d.notes or ())),
        main_metric_key=main,
        path=str(where),
        convergence=_convergence(ctx, d.convergence, "convergence", groups) if d.convergence is not None else None,
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

