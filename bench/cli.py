"""The ``bench`` command line.

    bench list                                   methods, tables, scenes
    bench scenes make RECIPE --out DIR           synthesise a scene into a dataset folder
    bench run --table NAME [--scale small] ...   run a table's jobs, write CSV / markdown / plot
    bench report [--out DIR]                     rebuild every table from stored results

Bad input (a missing file, a bad recipe, an unknown table) prints one line naming the file and the
problem and exits with status 2.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from bench.errors import BenchInputError

REPO_ROOT = Path(__file__).resolve().parent.parent
TABLES_DIR = REPO_ROOT / "configs" / "tables"
SCENES_DIR = REPO_ROOT / "configs" / "scenes"
DEFAULT_OUT = REPO_ROOT / "results" / "runs"


def _table_path(name: str) -> Path:
    path = TABLES_DIR / f"{name}.yaml"
    if not path.exists():
        from bench.tables import list_tables

        raise BenchInputError(path, f"no table {name!r} (known: {list_tables(TABLES_DIR)})")
    return path


def cmd_list(args: argparse.Namespace) -> int:
    from bench.tables import list_tables, load_table_spec
    from methods.registry import available_methods

    print("methods:")
    for m in available_methods():
        print(f"  {m}")
    print("tables:")
    avail = set(available_methods())
    for t in list_tables(TABLES_DIR):
        spec = load_table_spec(TABLES_DIR / f"{t}.yaml")
        missing = sorted({r.method for r in spec.rows if r.method not in avail})
        status = "ready" if not missing else f"pending methods: {', '.join(missing)}"
        print(f"  {t:10s} {spec.title}  [{status}]")
    print("scenes:")
    from bench.synth.recipe import load_recipe

    for p in sorted(SCENES_DIR.glob("*.yaml")):
        r = load_recipe(p)
        print(f"  {r.name:20s} {r.kind:8s} {r.format}")
    return 0


def cmd_scenes_make(args: argparse.Namespace) -> int:
    from bench.synth.make import make_dataset

    recipe = Path(args.recipe)
    if not recipe.exists() and (SCENES_DIR / f"{args.recipe}.yaml").exists():
        recipe = SCENES_DIR / f"{args.recipe}.yaml"
    info = make_dataset(recipe, args.out, scale=args.scale, seed=args.seed, overwrite=args.overwrite)
    print(f"wrote {info['path']} ({info['format']}, {info['views']} views {info['width']}x{info['height']}, "
          f"{info['bytes'] / 1e6:.1f} MB) in {info['seconds']:.2f} s")
    return 0


def _print_table_summary(md_path: Path) -> None:
    print(md_path.read_text())


def cmd_run(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from bench.report import build_table, collect_results, write_table_outputs
    from bench.runner import resolve_jobs, run_jobs
    from bench.tables import load_table_spec, plan_jobs
    from methods.registry import available_methods

    names = args.table
    if names == ["all"]:
        from bench.tables import list_tables

        names = list_tables(TABLES_DIR)
    out = Path(args.out) / args.scale
    for name in names:
        spec = load_table_spec(_table_path(name))
        plans = plan_jobs(spec, args.scale)
        if args.scenes:
            plans = [p for p in plans if p.scene in args.scenes]
        if args.seeds:
            plans = [replace(p, seed=s) for p in {(p.row, p.group, p.scene): p for p in plans}.values() for s in args.seeds]
        jobs, pending = resolve_jobs(plans)
        pending_methods = sorted({p.method for p in pending})
        print(f"table {name}: {len(jobs)} jobs to run or reuse at scale {args.scale!r}"
              + (f"; pending (not implemented yet): {', '.join(pending_methods)}" if pending_methods else ""))
        run_jobs(jobs, out, force=args.force, show_progress=not args.quiet)
        df = collect_results(out)
        if args.scenes or args.seeds:
            keep = {j.job_id for j in jobs}
            df = df[df["job_id"].isin(keep)]
        report = build_table(spec, df, args.scale, available_methods())
        paths = write_table_outputs(report, out)
        _print_table_summary(paths["md"])
        print(f"wrote {paths['csv']}, {paths['md']}, {paths['png']}")
    return 0


def cmd_report(args: argparse.Namespace) -> int:
    from bench.report import collect_results, render_report
    from bench.tables import list_tables, load_table_spec
    from methods.registry import available_methods

    out = Path(args.out) / args.scale
    names = args.table or list_tables(TABLES_DIR)
    specs = [load_table_spec(_table_path(n)) for n in names]
    path = render_report(specs, collect_results(out), args.scale, out, available_methods())
    print(f"wrote {path}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    from bench.synth.recipe import SCALES

    p = argparse.ArgumentParser(prog="bench", description="MonoInstance reference benchmark harness (CPU, small scenes).")
    sub = p.add_subparsers(dest="command", required=True)

    sub.add_parser("list", help="list methods, tables and scenes").set_defaults(func=cmd_list)

    scenes = sub.add_parser("scenes", help="scene datasets").add_subparsers(dest="scenes_command", required=True)
    make = scenes.add_parser("make", help="synthesise a recipe into a dataset folder in its on-disk format")
    make.add_argument("recipe", help="recipe YAML path, or a scene name from configs/scenes/")
    make.add_argument("--out", required=True, help="output dataset folder (written atomically)")
    make.add_argument("--scale", default="small", choices=SCALES)
    make.add_argument("--seed", type=int, default=None, help="override the recipe's seed")
    make.add_argument("--overwrite", action="store_true", help="replace an existing output folder")
    make.set_defaults(func=cmd_scenes_make)

    run = sub.add_parser("run", help="run a table's jobs and write its CSV, markdown and plot")
    run.add_argument("--table", required=True, nargs="+", help="table name(s) from configs/tables/, or 'all'")
    run.add_argument("--scale", default="small", choices=SCALES)
    run.add_argument("--scenes", nargs="+", default=None, help="restrict to these scenes")
    run.add_argument("--seeds", nargs="+", type=int, default=None, help="use these seeds instead of the table's")
    run.add_argument("--out", default=str(DEFAULT_OUT), help="results folder (a sub-folder per scale)")
    run.add_argument("--force", action="store_true", help="rerun jobs whose results exist")
    run.add_argument("--quiet", action="store_true", help="no progress bars")
    run.set_defaults(func=cmd_run)

    rep = sub.add_parser("report", help="rebuild tables and one report.md from stored results")
    rep.add_argument("--table", nargs="+", default=None)
    rep.add_argument("--scale", default="small", choices=SCALES)
    rep.add_argument("--out", default=str(DEFAULT_OUT))
    rep.set_defaults(func=cmd_report)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except BenchInputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except FileExistsError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
