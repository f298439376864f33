"""Where a table run's wall time went: each job's interval on its worker, the workers' idle time, the job
cost by kind.

Reads the job rows of a results folder (``bench run --out OUT``: ``OUT/SCALE/jobs/*.json``, through
:func:`bench.results_io.collect_results`, which skips the writer's temporaries and names a corrupt file). A finished row
records when its job started (``created``, UTC, whole seconds: :func:`bench.jobs.row_head`, written as the job
begins, after its dataset is prepared) and how long it took on its worker (``wall_seconds``), so the job ran in
``[created, created + wall_seconds]`` on ``worker_name``; a failed row is created when the job fails, so it
ran in ``[created - wall_seconds, created]``. Prints:

* the span (first start to last end), the job-seconds, and the workers' utilisation
  (job-seconds / (workers x span)): what the scheduling lost to idle cores;
* job-seconds, job count and mean job time per kind (method; a job without an optimisation schedule, the TSDF
  fusion references, marked "fusion only": :func:`bench.jobs.is_trained`) and per table;
* the longest idle gaps (a worker waiting while another still runs: the tail of the run).

``--png`` draws the run as a Gantt chart (one lane per worker, a bar per job, coloured by table row, or
``--colour-by method`` / ``table``).

Usage:
    .venv/bin/python scripts/run_timeline.py OUT [--scale small] [--png timeline.png] [--colour-by row]

Times are to the second (``created`` has whole seconds); a row without ``wall_seconds`` (a job that never
ran: failed before start) is skipped.
"""

from __future__ import annotations

import argparse
import datetime as _dt
from pathlib import Path
from typing import Any

import pandas as pd

from bench.jobs import is_trained
from bench.results_io import collect_results


def job_intervals(results: pd.DataFrame) -> pd.DataFrame:
    """Result rows (:func:`bench.results_io.collect_results`) -> one row per job that ran: ``job_id, table, row, method,
    scene, seed, worker, trained, start, end, seconds`` (start / end in seconds since the first start; worker =
    ``worker_name``; trained: :func:`bench.jobs.is_trained` of its config)."""
    recs = []
    for r in results.to_dict("records"):
        wall = r.get("wall_seconds")
        if wall is None or pd.isna(wall) or not r.get("created"):
            continue
        stamp = _dt.datetime.fromisoformat(str(r["created"])).timestamp()
        start = stamp if r["status"] == "ok" else stamp - float(wall)  # see the module docstring
        recs.append({"job_id": r["job_id"], "table": r["table"], "row": r["row"], "method": r["method"], "scene": r["scene"],
                     "seed": r["seed"], "worker": str(r.get("worker_name")), "trained": is_trained(r.get("config")),
                     "start": start, "end": start + float(wall), "seconds": float(wall)})
    df = pd.DataFrame(recs, columns=["job_id", "table", "row", "method", "scene", "seed", "worker", "trained", "start", "end",
                                     "seconds"])
    if len(df):
        t0 = df["start"].min()
        df["start"] -= t0
        df["end"] -= t0
    return df.sort_values("start", kind="stable").reset_index(drop=True)


def idle_gaps(df: pd.DataFrame, min_seconds: float = 5.0) -> pd.DataFrame:
    """Idle intervals of each worker between the run's start and its end (``worker, start, end, seconds``),
    those of at least ``min_seconds`` (shorter ones are the executor's hand-over and the rounding of
    ``created``)."""
    span_end = float(df["end"].max()) if len(df) else 0.0
    gaps = []
    for worker, jobs in df.groupby("worker"):
        t = 0.0
        jobs = jobs.sort_values("start")
        for s, e in zip(jobs["start"], jobs["end"]):  # a worker runs one job at a time
            if s - t >= min_seconds:
                gaps.append({"worker": worker, "start": t, "end": s, "seconds": s - t})
            t = max(t, e)
        if span_end - t >= min_seconds:
            gaps.append({"worker": worker, "start": t, "end": span_end, "seconds": span_end - t})
    return pd.DataFrame(gaps, columns=["worker", "start", "end", "seconds"]).sort_values("seconds", ascending=False)


def summary(df: pd.DataFrame) -> dict[str, Any]:
    """``span`` (s), ``job_seconds``, ``workers``, ``utilisation`` (job-seconds / (workers x span)),
    ``by_kind`` and ``by_table`` (DataFrames: jobs, job-seconds, mean seconds)."""
    span = float(df["end"].max() - df["start"].min()) if len(df) else 0.0
    workers = int(df["worker"].nunique())
    kind = df["method"].where(df["trained"], df["method"] + " (fusion only)")
    agg = {"jobs": ("seconds", "size"), "job_seconds": ("seconds", "sum"), "mean_seconds": ("seconds", "mean"),
           "max_seconds": ("seconds", "max")}
    return {"span": span, "job_seconds": float(df["seconds"].sum()), "workers": workers,
            "utilisation": float(df["seconds"].sum()) / (workers * span) if span > 0 else float("nan"),
            "by_kind": df.assign(kind=kind).groupby("kind").agg(**agg).sort_values("job_seconds", ascending=False),
            "by_table": df.groupby("table").agg(**agg)}


def gantt_png(df: pd.DataFrame, path: Path, colour_by: str = "row") -> None:
    """The run as a Gantt chart: one lane per worker, one bar per job coloured by ``colour_by`` (a column of
    :func:`job_intervals`: ``row``, ``method`` or ``table``); minutes on x."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch

    workers = sorted(df["worker"].unique())
    labels = list(dict.fromkeys(df[colour_by].astype(str)))  # in order of first appearance
    cmap = plt.get_cmap("tab20")
    colours = {m: cmap(i % 20) for i, m in enumerate(labels)}
    fig, ax = plt.subplots(figsize=(13, 1.2 + 0.5 * max(len(workers), len(labels) / 2.5)))
    for lane, w in enumerate(workers):
        jobs = df[df["worker"] == w]
        ax.broken_barh(list(zip(jobs["start"] / 60, jobs["seconds"] / 60)), (lane - 0.4, 0.8),
                       facecolors=[colours[str(m)] for m in jobs[colour_by]], edgecolor="white", linewidth=0.3)
    ax.set_yticks(range(len(workers)), workers)
    ax.set_xlabel("minutes since the first job started")
    ax.legend(handles=[Patch(color=colours[m], label=m) for m in labels], loc="center left", bbox_to_anchor=(1.01, 0.5),
              fontsize=7, frameon=False, title=colour_by, title_fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", type=Path, help="the results folder of a `bench run --out OUT`")
    ap.add_argument("--scale", default="small")
    ap.add_argument("--png", type=Path, default=None, help="write the Gantt chart here")
    ap.add_argument("--colour-by", choices=("row", "method", "table"), default="row", help="what the chart's colours tell apart")
    ap.add_argument("--gaps", type=int, default=5, help="how many of the longest idle gaps to list")
    args = ap.parse_args()
    results = collect_results(args.out / args.scale)
    if results.empty:
        raise SystemExit(f"run_timeline: no job rows in {args.out / args.scale / 'jobs'}")
    df = job_intervals(results)
    s = summary(df)
    print(f"{len(df)} jobs on {s['workers']} workers: span {s['span'] / 60:.1f} min, {s['job_seconds'] / 60:.1f} job-minutes, "
          f"utilisation {100 * s['utilisation']:.1f} %")
    with pd.option_context("display.float_format", "{:.1f}".format, "display.width", 160):
        print("\nby kind:\n" + s["by_kind"].to_string())
        print("\nby table (a job shared between tables is counted in the table that planned it first):\n" + s["by_table"].to_string())
        gaps = idle_gaps(df).head(args.gaps)
        print("\nlongest idle gaps (s, since the first start):\n" + (gaps.to_string(index=False) if len(gaps) else "none"))
    if args.png is not None:
        gantt_png(df, args.png, args.colour_by)
        print(f"\nwrote {args.png}")


if __name__ == "__main__":
    main()
