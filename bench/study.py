"""Convergence study: one method config on one scene over seeds, with dense snapshots along the schedule.

``bench study convergence METHOD SCENE`` answers "how many iterations does my method need": every run
(sweep value x seed) trains with ``--snapshots`` evenly spaced snapshots and records, per snapshot, the
scene protocol's metrics (F-score, accuracy, completion, ...), the method's own diagnostics (MonoSDF:
beta, every loss term averaged since the previous snapshot, the median rendered-depth error against GT
on training views) and the seconds spent. ``--exact-priors`` replaces the scene's monocular priors by its
GT depth and GT normals (the ceiling the priors allow; ``--exact-priors depth`` / ``normal`` replaces one of
the two and keeps the scene's other prior). ``--sweep KEY=V1,V2,...`` repeats the study for
each value of one config key. Writes ``study.csv`` (tidy: one line per run x snapshot),
``study.png`` (curves, mean over seeds, one colour per value) and ``study.md`` (final values and the
convergence checks of the issue tracker's criteria: F at 50 % within ``flat_tol`` of F at 100 %, no
snapshot after 25 % more than ``drop_tol`` below the one before).
"""

from __future__ import annotations

import dataclasses
import io
import json
import multiprocessing as mp
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path
from typing import Any, Callable

import numpy as np
import pandas as pd

from bench.convergence import ConvergenceSpec, check_run
from bench.data.atomic import atomic_write_bytes, atomic_write_text
from bench.data.errors import BenchInputError
from bench.overrides import parse_sweep
from bench.scales import is_smoke, smoke_note


@dataclasses.dataclass(frozen=True)
class StudyRun:
    """One training run of a study: the method, its config overrides (incl. the swept value), the scene
    (a recipe name or a dataset folder), the seed and the scale."""

    method: str
    scene: str
    scale: str
    seed: int
    overrides: dict[str, Any]
    exact_priors: str  # which priors are replaced by GT: "none" | "both" | "depth" | "normal" (EXACT_PRIORS)
    sweep_value: Any = None
    sweep_key: str | None = None
    mesh_dir: str | None = None  # every snapshot's mesh is written here (world metres, PLY; _write_meshes)

    @property
    def mesh_name(self) -> str:
        """File name of the final mesh: ``<key>=<value>_seed<seed>.ply`` (``run_seed<seed>.ply`` without a sweep)."""
        tag = f"{self.sweep_key}={json.dumps(self.sweep_value)}" if self.sweep_key else "run"
        return f"{tag}_seed{self.seed}.ply".replace("/", "_").replace(" ", "")


EXACT_PRIORS = ("none", "both", "depth", "normal")


def exact_priors_choice(value: bool | str) -> str:
    """``--exact-priors`` as one of :data:`EXACT_PRIORS` (``True`` = ``"both"``, ``False`` = ``"none"``)."""
    choice = ("both" if value else "none") if isinstance(value, bool) else str(value)
    if choice not in EXACT_PRIORS:
        raise ValueError(f"exact priors must be one of {EXACT_PRIORS}, got {value!r}")
    return choice


def load_study_scene(scene: str, scale: str, exact_priors: bool | str) -> Any:
    """The scene of a study: a recipe name (synthesised and cached) or a dataset folder; with
    ``exact_priors`` its mono depth and / or normals are replaced by GT depth / GT normals (camera frame):
    ``"both"`` (or ``True``) is the ceiling the priors allow; ``"depth"`` / ``"normal"`` replace one and keep
    the scene's other prior, which tells which of the two a failure comes from."""
    from bench.data.datasets import load_dataset
    from bench.data.formats import load_scene

    which = exact_priors_choice(exact_priors)
    sc = load_scene(Path(scene)) if Path(scene).is_dir() else load_dataset(scene, scale)
    if which != "none":
        if sc.gt_depth is None or sc.gt_normal is None:
            raise BenchInputError(sc.root or scene, "--exact-priors needs GT depth and GT normals in the dataset")
        exact = {"mono_depth": sc.gt_depth.copy(), "mono_normal": sc.gt_normal.copy()}
        keep = {"both": (), "depth": ("mono_normal",), "normal": ("mono_depth",)}[which]
        sc = dataclasses.replace(sc, **{k: v for k, v in exact.items() if k not in keep})
    return sc


def run_one(run: StudyRun, snapshots: int, stop_at: float = 1.0) -> list[dict[str, Any]]:
    """Train ``run`` with ``snapshots`` evenly spaced snapshots and evaluate each -> one record per snapshot.

    ``stop_at`` < 1 stops training after the snapshot at that fraction of the schedule (the learning-rate
    schedule is the full run's): a cheap screen of the early phase over many seeds, not a result."""
    from bench.evaluate import evaluate_snapshot
    from methods.registry import get_method, method_config

    scene = load_study_scene(run.scene, run.scale, run.exact_priors)
    protocol = scene.source_format  # each on-disk format has its protocol of the same name (bench/evaluate.py)
    fractions = [f for f in (round((i + 1) / snapshots, 6) for i in range(snapshots)) if f <= stop_at + 1e-9]
    overrides = {"fractions": fractions, **run.overrides}
    cfg = method_config(run.method, run.scale, overrides)
    if "diag_views" in cfg and not int(cfg["diag_views"]):
        cfg["diag_views"] = 4
    t0 = time.perf_counter()
    artifacts = get_method(run.method).fit(scene, cfg, run.seed, _progress_printer(run, t0))
    fit_s = time.perf_counter() - t0
    _write_meshes(run, artifacts.snapshots)  # before evaluating: a failed evaluation keeps the trained meshes
    records = []
    for snap in artifacts.snapshots:
        rec: dict[str, Any] = {"value": json.dumps(run.sweep_value), "seed": run.seed, "fraction": snap.fraction,
                               "iterations": snap.iterations, "seconds": snap.seconds, "fit_seconds": fit_s}
        try:
            rec.update(evaluate_snapshot(snap, scene, protocol, run.scale, seed=run.seed))
        except ValueError as exc:  # an empty mesh: the point has no metrics
            rec["error"] = str(exc)
        rec.update({k: v for k, v in snap.diagnostics.items() if isinstance(v, (int, float))})
        records.append(rec)
    return records


def _write_meshes(run: StudyRun, snapshots: list[Any]) -> None:
    """Every snapshot's mesh (world metres, binary PLY) into ``run.mesh_dir``: the final one as
    :attr:`StudyRun.mesh_name`, the others with ``_it<iterations>`` before the suffix; empty meshes skipped."""
    if not run.mesh_dir:
        return
    for i, snap in enumerate(snapshots):
        mesh = snap.mesh
        if mesh is None or not len(mesh.faces):
            continue
        name = run.mesh_name if i == len(snapshots) - 1 else run.mesh_name.replace(".ply", f"_it{snap.iterations}.ply")
        path = Path(run.mesh_dir) / name
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(path, mesh.export(file_type="ply", encoding="binary"))


def _progress_printer(run: StudyRun, t0: float, every: float = 0.1) -> Callable[[float, str], None]:
    """A progress callback that prints one line per ``every`` of the schedule (stderr: the study's log),
    so a long study shows where each run stands, not only when it ends."""
    state = {"next": every}

    def show(frac: float, msg: str) -> None:
        if frac + 1e-9 >= state["next"]:
            state["next"] = (int(frac / every + 1e-9) + 1) * every
            label = f" value {json.dumps(run.sweep_value)}" if run.sweep_value is not None else ""
            print(f"[study] seed {run.seed}{label}: {frac:4.0%} {msg} ({time.perf_counter() - t0:.0f} s)", file=sys.stderr, flush=True)

    return show


def _worker_init() -> None:
    from bench.executors.base import set_job_threads
    from bench.executors.lifeline import exit_with_parent, ignore_interrupts

    exit_with_parent()  # a killed study leaves no worker training on (bench.executors.lifeline)
    ignore_interrupts()  # Ctrl-C is the study's to handle: it terminates the workers
    set_job_threads(1)


def convergence_checks(curve: pd.DataFrame, spec: ConvergenceSpec = ConvergenceSpec()) -> dict[str, Any]:
    """The issue tracker's convergence criteria on one run's curve of ``spec.metric`` (:mod:`bench.convergence`):
    ``flat``: the value at the snapshot nearest 50 % within ``spec.flat`` of the final one; ``no_drop``: no
    snapshot after 25 % more than ``spec.drop`` worse than the one before (worse in the metric's direction)."""
    v = curve[spec.metric] if spec.metric in curve else np.full(len(curve), np.nan)
    c = check_run(curve["fraction"].to_numpy(dtype=float), np.asarray(v, dtype=float), spec)
    return {"flat": c.flat, "no_drop": c.no_drop, "half": c.half, "max_drop": c.max_drop}


def study_convergence_spec(protocol: str, tables_dir: Path | None = None) -> ConvergenceSpec:
    """The criteria a study judges its runs by: those of the first table spec in ``tables_dir`` (by name)
    that evaluates ``protocol`` and states criteria (DTU: the Chamfer distance of Table 2; ScanNet / Replica:
    the F-score of Tables 1 / 4 / 5), so a study and the table it prepares judge alike; the F-score defaults
    of :class:`ConvergenceSpec` when no table does. ``tables_dir``: default the shipped configs/tables/."""
    from bench.pipeline import SHIPPED_TABLES
    from bench.table_spec import list_tables, load_table_spec

    tables_dir = SHIPPED_TABLES if tables_dir is None else tables_dir

    for name in list_tables(tables_dir):
        spec = load_table_spec(Path(tables_dir) / f"{name}.yaml")
        if spec.convergence is not None and any(g.protocol == protocol for g in spec.groups):
            return spec.convergence
    return ConvergenceSpec()


def summarise(df: pd.DataFrame, key: str | None, spec: ConvergenceSpec = ConvergenceSpec()) -> str:
    """Markdown: per sweep value, final metrics mean ± std over seeds and the convergence checks of ``spec``
    (its metric is the headline column)."""
    m = spec.metric
    lines = [f"| {key or 'config'} | seeds | {m} final | {m} std | {m} at 50 % | Acc | Comp | depth err (m) | beta | flat (all seeds) | no drop (all seeds) | s / run |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    fmt = ".3f" if spec.higher_is_better else ".4f"
    for value, g in df.groupby("value", sort=False):
        finals, checks = [], []
        for _, run in g.groupby("seed"):
            run = run.sort_values("fraction")
            finals.append(run.iloc[-1])
            checks.append(convergence_checks(run, spec))
        fin = pd.DataFrame(finals)

        def ms(col: str, fmt: str = ".3f") -> str:
            if col not in fin or fin[col].isna().all():
                return "-"
            return f"{fin[col].mean():{fmt}}"

        m_std = f"{fin[m].std(ddof=0):{fmt}}" if m in fin else "-"
        half = np.nanmean([c["half"] for c in checks])
        lines.append(f"| {value} | {len(fin)} | {ms(m, fmt)} | {m_std} | {half:{fmt}} | {ms('acc')} | {ms('comp')} | {ms('depth_err_median', '.4f')} "
                     f"| {ms('beta', '.4f')} | {all(c['flat'] for c in checks)} | {all(c['no_drop'] for c in checks)} | {ms('fit_seconds', '.0f')} |")
    criteria = (f"Criteria ({m}, `bench.study.study_convergence_spec`): flat = value at 50 % within {spec.flat:g} of the final; "
                f"no drop = no snapshot after 25 % more than {spec.drop:g} {'below' if spec.higher_is_better else 'above'} the one before; "
                f"a table row also needs the seed std <= {spec.seed_std:g}.")
    return "\n".join(lines) + "\n\n" + criteria + "\n"


PLOT_PANELS = (("fscore", "F-score"), ("cd", "Chamfer (m)"), ("acc", "Acc (m)"), ("comp", "Comp (m)"), ("depth_err_median", "median |depth - GT| (m)"),
               ("beta", "beta"), ("loss_color", "colour loss"))


def plot_study(df: pd.DataFrame, title: str) -> bytes:
    """PNG: one panel per quantity against iterations; per sweep value the mean over seeds (thick) and
    each seed (thin)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    panels = [(c, lab) for c, lab in PLOT_PANELS if c in df and df[c].notna().any()]
    fig = Figure(figsize=(4.2 * len(panels), 3.6))
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, len(panels), squeeze=False)[0]
    colours = {v: f"C{i % 10}" for i, v in enumerate(dict.fromkeys(df["value"]))}
    for ax, (col, lab) in zip(axes, panels):
        for value, g in df.groupby("value", sort=False):
            for _, run in g.groupby("seed"):
                run = run.sort_values("iterations")
                ax.plot(run["iterations"], run[col], color=colours[value], lw=0.6, alpha=0.5)
            mean = g.groupby("iterations")[col].mean()
            ax.plot(mean.index, mean.values, color=colours[value], lw=2, marker="o", ms=3, label=str(value))
        ax.set_xlabel("iterations")
        ax.set_title(lab, fontsize=9)
        if col in ("depth_err_median", "beta"):
            ax.set_yscale("log")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7, title="value", title_fontsize=7)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    return buf.getvalue()


def run_study(method: str, scene: str, scale: str, seeds: list[int], overrides: dict[str, Any], sweep: str | None,
              exact_priors: bool | str, snapshots: int, out_dir: Path, workers: int | None = None,
              log: Callable[[str], None] = print, stop_at: float = 1.0) -> pd.DataFrame:
    """Run every (sweep value x seed), write study.csv / study.png / study.md into ``out_dir``; returns the
    records. ``stop_at`` < 1: every run stops at that fraction of its schedule (see :func:`run_one`)."""
    from methods.registry import method_config

    if snapshots < 2:
        raise BenchInputError("--snapshots", f"need at least 2 snapshots, got {snapshots}")
    if not 1.0 / snapshots <= stop_at <= 1.0:
        raise BenchInputError("--stop-at", f"must lie in [1 / snapshots, 1] = [{1.0 / snapshots:g}, 1], got {stop_at:g}")
    key, values = parse_sweep(sweep)
    method_config(method, scale, {**overrides, **({key: values[0]} if key else {})})  # unknown keys: one clear error, before any work
    exact_priors = exact_priors_choice(exact_priors)
    protocol = load_study_scene(scene, scale, exact_priors).source_format  # bad scene: fail now (and synthesise it once, before the workers)
    spec = study_convergence_spec(protocol)
    mesh_dir = str(Path(out_dir) / "meshes")
    runs = [StudyRun(method, scene, scale, int(s), {**overrides, **({key: v} if key else {})}, exact_priors, v, key, mesh_dir)
            for v in values for s in seeds]
    workers = max(1, min(workers or os.cpu_count() or 1, len(runs)))
    exact_label = {"none": "", "both": ", exact priors", "depth": ", exact depth prior", "normal": ", exact normal prior"}[exact_priors]
    exact_label += ", smoke test: not a result" if is_smoke(scale) else ""  # in the log, study.md and study.png
    log(f"[study] {method} on {scene} ({scale}{exact_label}): {len(runs)} runs "
        f"({len(values)} value(s) x {len(seeds)} seed(s)), {snapshots} snapshots each, {workers} worker(s)")
    if is_smoke(scale):
        log(f"[study] {smoke_note(scale)}")
    records: list[dict[str, Any]] = []
    t0 = time.perf_counter()
    title = f"{method} on {scene} ({scale}{exact_label}); {overrides or ''}"
    out_dir = Path(out_dir)
    df = pd.DataFrame()
    from bench.executors.lifeline import FORKSERVER_PRELOAD, mark_parent

    mark_parent()
    ctx = mp.get_context("forkserver")
    ctx.set_forkserver_preload(FORKSERVER_PRELOAD)
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_worker_init)
    try:
        futures = {pool.submit(run_one, r, snapshots, stop_at): r for r in runs}
        for fut in as_completed(futures):
            r = futures[fut]
            recs = fut.result()
            records.extend(recs)
            last = recs[-1]
            m_str = ", ".join(f"{x.get(spec.metric, float('nan')):.4g}" for x in recs)
            log(f"[study] {f'{key}={r.sweep_value} ' if key else ''}seed {r.seed}: {spec.metric} along the schedule {m_str}; "
                f"depth err {last.get('depth_err_median', float('nan')):.4f} m; beta {last.get('beta', float('nan')):.4f}; "
                f"{last['fit_seconds']:.0f} s ({time.perf_counter() - t0:.0f} s elapsed)")
            df = _write_outputs(records, values, key, out_dir, title + (f"; stopped at {stop_at:.0%} of the schedule" if stop_at < 1 else ""),
                                seeds, snapshots, spec)  # after every run: a partial study is readable
    except BaseException:  # Ctrl-C / SIGTERM / a failed run: stop the running workers too, not only the queue
        for proc in list(getattr(pool, "_processes", {}).values()):
            proc.terminate()
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    pool.shutdown()
    log((out_dir / "study.md").read_text())
    return df


def _write_outputs(records: list[dict[str, Any]], values: list[Any], key: str | None, out_dir: Path, title: str,
                   seeds: list[int], snapshots: int, spec: ConvergenceSpec = ConvergenceSpec()) -> pd.DataFrame:
    """study.csv / study.png / study.md from the runs finished so far (each written atomically)."""
    df = pd.DataFrame(records)
    order = {json.dumps(v): i for i, v in enumerate(values)}
    df = df.sort_values(by=["value", "seed", "fraction"], key=lambda c: c.map(order) if c.name == "value" else c).reset_index(drop=True)
    df.insert(0, "sweep_key", key or "")
    out_dir.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out_dir / "study.csv", df.to_csv(index=False))
    atomic_write_bytes(out_dir / "study.png", plot_study(df, title))
    md = (f"# Convergence study: {title}\n\nseeds {seeds}; {snapshots} snapshots; sweep {key or '-'} over {values}\n\n"
          + summarise(df, key, spec) + "\n![curves](study.png)\n")
    atomic_write_text(out_dir / "study.md", md)
    return df
