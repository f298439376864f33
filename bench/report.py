"""A table's report: build it from the stored results and write its outputs.

:func:`build_table`: the results of the table's planned jobs (matched by id, :func:`bench.aggregate.select_by_id`)
aggregated into cells, timings and convergence verdicts (:mod:`bench.aggregate`), and its claims checked
(:mod:`bench.claims`). :func:`write_table_outputs`: the tidy CSV, the timings and curve CSVs, the markdown
(:mod:`bench.table_markdown`) and the figures (:mod:`bench.figures`) of one table; :func:`render_report`
also one ``report.md`` assembling several tables. Stored result rows are read by :mod:`bench.results_io`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Iterable, Mapping, Sequence

import pandas as pd

from bench.aggregate import PlanIndex, curve_table, judge_rows, select_by_id, table_cells, tidy_frame, timing_frame
from bench.claims import check_claim
from bench.data.atomic import atomic_write_many, atomic_write_text
from bench.results_io import empty_results
from bench.scales import is_smoke, smoke_note
from bench.table_markdown import to_markdown
from bench.table_report import TableReport
from bench.table_spec import TableSpec


def build_table(spec: TableSpec, df: pd.DataFrame, scale: str,
                available_methods: Iterable[str] | None = None, *, plans: PlanIndex) -> TableReport:
    """Aggregate the jobs of ``spec`` at ``scale`` into cells, timings and claim verdicts.

    ``available_methods``: names in the method registry; rows whose method is not among them (and
    which have no results) read "pending (method not implemented yet)". None means all are available.
    ``plans``: the table's job ids (:func:`bench.runner.plan_index`): results are matched by id, so
    jobs shared with other tables count.
    """
    jobs, n_unmatched, n_superseded = select_by_id(spec, df if df is not None else empty_results(), scale, plans)
    return report_from_jobs(spec, scale, jobs, available_methods, n_unmatched, n_superseded)


def report_from_jobs(spec: TableSpec, scale: str, jobs: pd.DataFrame, available_methods: Iterable[str] | None = None,
                     n_unmatched: int = 0, n_superseded: int = 0) -> TableReport:
    """The report of ``spec`` at ``scale`` from its matched jobs (one per row x group x scene x seed, the
    group in a ``gid`` column, as :func:`bench.aggregate.select_by_id` returns them); ``n_unmatched`` and
    ``n_superseded``: the results the matching left out, shown in the markdown. See :func:`build_table`."""
    avail = None if available_methods is None else set(available_methods)
    unavailable = {r.method for r in spec.rows if r.method is not None and avail is not None and r.method not in avail}
    cells = table_cells(spec, jobs, scale, unavailable)
    convergence = judge_rows(spec, jobs, scale)
    report = TableReport(spec, scale, cells, jobs, tidy_frame(spec, cells, convergence), timing_frame(spec, jobs), [], unavailable,
                         n_unmatched, n_superseded, convergence)
    report.claims = [check_claim(report, c) for c in spec.claims]
    return report


def write_table_outputs(report: TableReport, out_dir: str | Path, figures: bool = True) -> dict[str, Path]:
    """Write ``<table>.csv``, ``<table>_time.csv``, ``<table>_curve.csv`` (accuracy along the schedule,
    :func:`bench.aggregate.curve_table`), ``<table>.md`` and ``<table>_accuracy_vs_time.png`` atomically into
    ``out_dir``; with ``figures`` and kept meshes also ``<table>_reconstructions.png``
    (:func:`bench.figures.reconstruction_figure`), embedded in the markdown. Returns the paths by kind."""
    out, name = Path(out_dir), report.spec.name
    paths = {"csv": out / f"{name}.csv", "time_csv": out / f"{name}_time.csv", "curve_csv": out / f"{name}_curve.csv",
             "md": out / f"{name}.md", "png": out / f"{name}_accuracy_vs_time.png"}
    curves = curve_table(report)
    files: dict[Path, bytes] = {paths["csv"]: report.tidy.to_csv(index=False).encode(),
                                paths["time_csv"]: report.timing.to_csv(index=False).encode(),
                                paths["curve_csv"]: curves.to_csv(index=False).encode()}
    from bench.figures import plot_accuracy_vs_time, reconstruction_figure, renders_figure, uncertainty_figure

    extra = ""
    for kind, make, caption in (
        ("reconstructions", reconstruction_figure, "Reconstructions (first scene, first seed of each group, from 2 training cameras): "
         "each pixel coloured by the distance of the surface it sees to the GT mesh (0-10 cm; grey: no surface)."),
        ("uncertainty", uncertainty_figure, "Estimated uncertainty beside the true error of the depth prior (|prior aligned "
         "to GT by per-view scale + shift - GT|), 3 views of the first scene and seed."),
        ("renders", renders_figure, "Test-view renders beside the GT images, rendered depth beside the GT depth "
         "(first scene and seed)."),
    ):
        png = make(report, out) if figures else None
        if png is not None:
            paths[f"{kind}_png"] = out / f"{name}_{kind}.png"
            files[paths[f"{kind}_png"]] = png
            extra += f"\n![{kind}]({paths[f'{kind}_png'].name})\n\n{caption}\n"
    files[paths["md"]] = (to_markdown(report, heading_level=1) + f"\n![accuracy vs time]({paths['png'].name})\n" + extra).encode()
    files[paths["png"]] = plot_accuracy_vs_time(report, curves)
    atomic_write_many(files)  # all of a table's outputs or none (a full disk leaves the previous set)
    return paths


def render_report(specs: Sequence[TableSpec], df: pd.DataFrame, scale: str, out_dir: str | Path,
                  available_methods: Iterable[str] | None = None, title: str = "MonoInstance benchmark report",
                  *, plans: Mapping[str, PlanIndex]) -> Path:
    """Build and write every table's outputs into ``out_dir`` and one ``report.md`` assembling them.

    ``plans``: per table name, its job ids (see :func:`build_table`). Returns the path of
    ``report.md``. Raises BenchInputError if a spec does not define ``scale``.
    """
    out = Path(out_dir)
    avail = None if available_methods is None else set(available_methods)
    reports = [build_table(s, df, scale, avail, plans=plans[s.name]) for s in specs]
    sections = [f"# {title}", "", f"Scale: `{scale}`. Jobs read: {len(df)}.", ""]
    if is_smoke(scale):
        sections += [f"**Smoke test.** {smoke_note(scale)}", ""]
    if len(df):
        scales = sorted({str(v) for v in df["scale"].unique()})
        versions = sorted({f"{k} {v}" for vs in df["versions"] for k, v in vs.items()})
        cpus = sorted({str(c) for c in (df["cpu"] if "cpu" in df else []) if c})  # times depend on it (bench.machine)
        sections.append(f"Scales present in the results: {', '.join(scales)}. "
                        f"Versions: {', '.join(versions) or 'not recorded'}. "
                        f"CPUs (times depend on them): {'; '.join(cpus) or 'not recorded'}.")
    sections += ["", "Tables:"] + [f"- [{r.spec.title}]({r.spec.name}.md)" for r in reports] + [""]
    for r in reports:
        paths = write_table_outputs(r, out)
        sections += [to_markdown(r, heading_level=2), f"![accuracy vs time]({r.spec.name}_accuracy_vs_time.png)", ""]
        sections += [f"![{k[:-4]}]({p.name})\n" for k, p in paths.items() if k.endswith("_png") and k != "png"]
    path = out / "report.md"
    atomic_write_text(path, "\n".join(sections))
    return path
