"""The ``bench`` command line.

    bench list                                   methods, tables, scenes
    bench config METHOD [--scale S] [--set K=V]  a method's resolved, checked config (value and type per key)
    bench scenes make RECIPE --out DIR           synthesise a scene into a dataset folder
    bench scenes downsize SRC DST --factor N     a dataset folder at 1/N of its image size, same format
    bench scenes card RECIPE|DIR [--scale S] [--seed N] [--out FILE.md]
                                                 the scene's datasheet beside real-data anchors (docs/datasheet.md);
                                                 several scenes: one summary table
    bench run --table NAME [--scale small] ...   run a table's jobs, write CSV / markdown / plot
              [--executor local|dask] [--workers N] [--scheduler tcp://HOST:PORT] [--retries R]
    bench regress --table NAME [--scale small] [--update-reference]
                                                 fresh run vs results/reference/<scale>/<table>.json
    bench report [--out DIR]                     rebuild every table from stored results
    bench fit METHOD PATH [--scale S] [--set K=V] [--out DIR]
                                                 one method on your own dataset folder; metrics where GT exists
    bench study convergence METHOD SCENE [--seeds 0 1 2] [--snapshots 8] [--exact-priors [depth|normal]]
              [--set KEY=VALUE ...] [--sweep KEY=V1,V2] [--out DIR]
                                                 F-score / depth error / beta / losses along the schedule

Exit status: 0 everything ran; 1 (``bench run``) the tables were written but some job failed; 2 bad
input (a missing file, a bad recipe, an unknown table or scene, an unwritable ``--out``, filters that
match no job): one line naming the file and the problem; 130 interrupted (Ctrl-C, SIGTERM); 141 the
reader of the output closed the pipe (``bench list | head``). Never a traceback.
"""

from __future__ import annotations

import argparse
import contextlib
import sys
from pathlib import Path
from typing import Iterator

from bench.data.errors import BenchInputError

EXIT_JOBS_FAILED = 1
EXIT_BROKEN_PIPE = 141  # 128 + SIGPIPE, what a shell tool killed by a closed pipe returns
REPO_ROOT = Path(__file__).resolve().parent.parent
SCENES_DIR = REPO_ROOT / "configs" / "scenes"
DEFAULT_OUT = REPO_ROOT / "results" / "runs"
REFERENCE_DIR = REPO_ROOT / "results" / "reference"


def table_status(spec, available: set[str]) -> str:
    """"ready", or what keeps the table from running: missing methods, an unsupported evaluation
    protocol, or row/group overrides a method's config does not have."""
    from bench.evaluate import SUPPORTED_PROTOCOLS
    from methods.registry import method_config

    problems = sorted({f"method {r.method}" for r in spec.rows if r.method not in available})
    problems += sorted({f"protocol {g.protocol}" for g in spec.groups if g.protocol not in SUPPORTED_PROTOCOLS})
    for r in spec.rows:
        for g in spec.groups:
            if r.method in available:
                try:
                    method_config(r.method, spec.scales[0], {**g.overrides, **r.overrides})
                except BenchInputError as exc:
                    problems.append(f"config of {r.method!r}: {exc.problem.split(' (keys')[0]}")
    problems = list(dict.fromkeys(problems))
    return "ready" if not problems else "pending: " + "; ".join(problems[:3]) + (" ..." if len(problems) > 3 else "")


def cmd_list(args: argparse.Namespace) -> int:
    from bench.pipeline import load_tables
    from methods.registry import available_methods

    print("methods:")
    for m in available_methods():
        print(f"  {m}")
    print("tables:")
    avail = set(available_methods())
    for spec in load_tables(["all"], Path(args.tables_dir)):
        status = table_status(spec, avail)
        print(f"  {spec.name:10s} {spec.title}  [{status}]")
    print("scenes:")
    from bench.data.synth.recipe import load_recipe

    for p in sorted(SCENES_DIR.glob("*.yaml")):
        r = load_recipe(p)
        print(f"  {r.name:20s} {r.kind:8s} {r.format}")
    legacy = sorted(p.relative_to(SCENES_DIR).with_suffix("").as_posix() for p in (SCENES_DIR / "legacy").glob("*.yaml"))
    if legacy:
        print(f"  earlier room scenes, kept for the record (in no table): {' '.join(legacy)}")
    from bench.machine import cpu_description
    from bench.mkl_dispatch import blas_path, mkl_code_path

    print(f"CPU: {cpu_description()} (recorded in every job row: times depend on it)")
    print(f"matrix products: MKL {mkl_code_path()} path (blas: {blas_path()}; bench/mkl_dispatch.py)")
    return 0


def cmd_scenes_make(args: argparse.Namespace) -> int:
    from bench.data.synth.make import make_dataset

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
    """Plan every named table, run the union of their jobs once (a job several tables share, same id,
    runs once and counts in each), then write each table's outputs; with several tables also one
    ``report.md`` assembling them."""
    from bench.pipeline import load_tables, plan_table
    from bench.report import build_table, render_report, write_table_outputs
    from bench.results_io import collect_results
    from bench.runner import plan_index, run_jobs, unique_jobs
    from bench.scales import is_smoke, smoke_note
    from methods.registry import available_methods

    out = Path(args.out) / args.scale
    specs, jobs_by_table = [], {}
    threads = _planned_threads(args)
    for spec in load_tables(args.table, Path(args.tables_dir)):
        planned = plan_table(spec, args.scale, args.rows, args.scenes, args.seeds, threads)
        jobs, pending = planned.jobs, planned.pending
        pending_methods = sorted({p.method for p in pending})
        print(f"table {spec.name}: {len(jobs)} jobs at scale {args.scale!r}"
              + (f"; pending (not implemented yet): {', '.join(pending_methods)}" if pending_methods else ""))
        specs.append(spec)
        jobs_by_table[spec.name] = jobs  # by the spec's name: a table given by path is named inside its file
    if is_smoke(args.scale):
        print(smoke_note(args.scale))
    names = list(jobs_by_table)
    every = [j for name in names for j in jobs_by_table[name]]
    todo = unique_jobs(every)
    if not todo:
        raise BenchInputError("bench run", f"nothing to run: no implemented job in table(s) {names} at scale {args.scale!r}"
                              " with these filters")
    if len(names) > 1:
        print(f"{len(todo)} distinct jobs for {len(every)} table cells x seeds ({len(every) - len(todo)} shared between tables)")
    with output_folder(out), _executor(args) as executor:
        rows = run_jobs(todo, out, force=args.force, show_progress=not args.quiet, executor=executor,
                        keep_artifacts=not args.no_artifacts)
    failed = [r for r in rows if r.get("status") != "ok"]
    status = EXIT_JOBS_FAILED if failed else 0
    if failed:
        print(f"{len(failed)} of {len(rows)} jobs failed (their cells show 'failed'; rerun retries them): exit {status}",
              file=sys.stderr)
    df = collect_results(out)
    plans_by_table = {name: plan_index(jobs) for name, jobs in jobs_by_table.items()}
    if len(specs) > 1:
        path = render_report(specs, df, args.scale, out, available_methods(), plans=plans_by_table)
        print(f"wrote {path} (and each table's CSV, markdown and plot)")
        return status
    report = build_table(specs[0], df, args.scale, available_methods(), plans=plans_by_table[specs[0].name])
    paths = write_table_outputs(report, out)
    _print_table_summary(paths["md"])
    print(f"wrote {', '.join(str(p) for p in paths.values())}")
    return status


def check_writable(out: Path) -> None:
    """Fail before any job runs when ``out`` cannot be created or written (a file in the way, read-only,
    no space for even a probe file)."""
    import tempfile

    if out.exists() and not out.is_dir():
        raise BenchInputError(str(out), "is a file, not a folder (--out names the output folder)")
    try:
        out.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=out, prefix=".probe-"):
            pass
    except OSError as exc:
        raise BenchInputError(str(out), f"output folder is not writable: {exc.strerror or exc}") from None


@contextlib.contextmanager
def output_folder(out: Path) -> Iterator[None]:
    """Create ``out`` (:func:`check_writable`) for the block; if the block is interrupted or fails, remove the
    empty folders left in ``out`` and ``out`` itself (with the parents this created) when empty: a run stopped
    before its first result leaves no empty folder behind. Folders holding any file are kept."""
    created = [p for p in (out, *out.parents) if not p.exists()]
    check_writable(out)
    try:
        yield
    except BaseException:
        for folder in sorted((p for p in out.rglob("*") if p.is_dir()), key=lambda p: len(p.parts), reverse=True):
            with contextlib.suppress(OSError):
                folder.rmdir()  # only if empty
        for folder in created:  # deepest first
            try:
                folder.rmdir()
            except OSError:
                break
        raise


def _workers(args: argparse.Namespace) -> int | None:
    """``--workers``, or for the local executor one single-threaded job per core: 2 x 1-thread MonoSDF
    jobs do 0.67 M samples/s in total, one 2-thread job 0.53 M (benchmarks/bench_monosdf_step.py,
    docs/performance.md)."""
    if args.workers is None and args.executor == "local":
        from bench.executors.base import available_cores

        return available_cores()
    return args.workers


def _planned_threads(args: argparse.Namespace) -> int | None:
    """The torch threads per job the ``--executor / --workers`` flags will give (None: decided per worker)."""
    from bench.executors.base import threads_per_job

    if args.executor != "local":
        return None
    return threads_per_job(max(1, _workers(args) or 1))


def _executor(args: argparse.Namespace):
    """The executor the ``--executor / --workers / --scheduler / --retries`` flags ask for."""
    from bench.executors import make_executor

    if args.workers is not None and args.workers < 1:
        raise BenchInputError("--workers", f"must be >= 1, got {args.workers}")
    if args.retries < 0:
        raise BenchInputError("--retries", f"must be >= 0, got {args.retries}")
    if args.scheduler is not None and args.executor != "dask":
        raise BenchInputError("--scheduler", "only with --executor dask")
    return make_executor(args.executor, workers=_workers(args), scheduler=args.scheduler, retries=args.retries)


def _add_tables_dir(p: argparse.ArgumentParser) -> None:
    from bench.pipeline import SHIPPED_TABLES

    p.add_argument("--tables-dir", default=str(SHIPPED_TABLES), metavar="DIR",
                   help="where table names resolve (default: the shipped configs/tables/)")


def _add_executor_flags(p: argparse.ArgumentParser) -> None:
    from bench.executors import DEFAULT_RETRIES, EXECUTORS

    p.add_argument("--executor", default="local", choices=EXECUTORS,
                   help="where jobs run: local processes (default) or a Dask cluster (docs/scale-out.md)")
    p.add_argument("--workers", type=int, default=None,
                   help="local: parallel worker processes, one torch thread each when workers = cores "
                        "(default: one per core; 1 runs the jobs in this process); "
                        "dask without --scheduler: size of a local cluster (default 2)")
    p.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT",
                   help="dask: address of a running scheduler (default: start a local cluster)")
    p.add_argument("--retries", type=int, default=DEFAULT_RETRIES,
                   help=f"resubmissions of a job whose worker died (default {DEFAULT_RETRIES})")


def cmd_regress(args: argparse.Namespace) -> int:
    from bench.regress import run_regress

    with _executor(args) as executor:
        return run_regress(args, executor, Path(args.tables_dir))


def cmd_report(args: argparse.Namespace) -> int:
    from bench.pipeline import load_tables, plan_table
    from bench.report import render_report
    from bench.results_io import collect_results
    from bench.runner import plan_index
    from methods.registry import available_methods

    out = Path(args.out) / args.scale
    specs = load_tables(args.table or ["all"], Path(args.tables_dir))
    plans = {s.name: plan_index(plan_table(s, args.scale).jobs) for s in specs}
    path = render_report(specs, collect_results(out), args.scale, out, available_methods(), plans=plans)
    print(f"wrote {path}")
    return 0


def cmd_study_convergence(args: argparse.Namespace) -> int:
    from bench.overrides import parse_overrides
    from bench.study import run_study

    overrides = parse_overrides(args.set)
    out = Path(args.out) if args.out else DEFAULT_OUT / "studies" / f"{args.method}-{Path(args.scene).name}-{args.scale}"
    run_study(args.method, args.scene, args.scale, list(args.seeds), overrides, args.sweep, args.exact_priors, int(args.snapshots),
              out, workers=args.workers, stop_at=float(args.stop_at))
    return 0


def cmd_scenes_downsize(args: argparse.Namespace) -> int:
    from bench.data.formats.downsize import downsize_folder

    small = downsize_folder(Path(args.src), Path(args.dst), int(args.factor), overwrite=args.overwrite)
    print(f"wrote {args.dst} ({small.source_format}, {small.num_views} views {small.width}x{small.height})")
    return 0


def cmd_scenes_card(args: argparse.Namespace) -> int:
    """Print the datasheet card of a recipe (synthesised in memory) or a dataset folder with GT; with
    ``--out`` also write it (and its plot, FILE.png) there."""
    from bench.data.datasheet import render_card, write_card
    from bench.data.datasheet.card import render_summary
    from bench.data.datasheet.source import card_sheet

    if len(args.target) > 1:  # several scenes: one summary table (the README's)
        if args.out:
            raise BenchInputError("--out", "writes one scene's card: give one RECIPE|DIR")
        print(render_summary({t: card_sheet(t, args.scale, args.seed, SCENES_DIR) for t in args.target}), end="")
        return 0
    sheet = card_sheet(args.target[0], args.scale, args.seed, SCENES_DIR)
    print(render_card(sheet), end="")
    if args.out:
        out = Path(args.out)
        check_writable(out.parent)
        paths = write_card(sheet, out)
        print(f"wrote {', '.join(str(p) for p in paths)}")
    return 0


def cmd_config(args: argparse.Namespace) -> int:
    """Print a method's config as a job would get it (YAML defaults <- scale preset <- ``--set``), checked
    against the method's typed config, one ``key: value  # type`` line per key."""
    import json
    from typing import get_type_hints

    from bench.data.config import describe_type
    from bench.overrides import parse_overrides
    from methods.registry import config_type, method_config

    cfg = method_config(args.method, args.scale, parse_overrides(args.set))
    ctype = config_type(args.method)
    hints = get_type_hints(ctype, include_extras=True) if ctype is not None else {}
    width = max((len(k) for k in cfg), default=0)
    print(f"# method {args.method!r}, scale {args.scale!r}" + (f", overrides {parse_overrides(args.set)}" if args.set else "")
          + (f" (typed: {ctype.__module__}.{ctype.__name__})" if ctype is not None else " (a plugin without config_type: unchecked)"))
    for key, value in cfg.items():
        kind = f"  # {describe_type(hints[key])}" if key in hints else ""
        print(f"{key:<{width}}  {json.dumps(value)}{kind}")
    return 0


def cmd_fit(args: argparse.Namespace) -> int:
    from bench.fit import fit_folder
    from bench.overrides import parse_overrides

    if args.seed < 0:
        raise BenchInputError("--seed", f"must be a non-negative integer, got {args.seed}")
    out = Path(args.out) if args.out else DEFAULT_OUT / "fit" / f"{args.method}-{Path(args.path).resolve().name}-{args.scale}"
    with output_folder(out):  # a bad folder or method leaves no empty output folder behind
        fit_folder(args.method, Path(args.path), args.scale, parse_overrides(args.set), out, seed=args.seed, factor=args.factor)
    return 0


def build_parser() -> argparse.ArgumentParser:
    from bench.data.synth.recipe import SCALES

    p = argparse.ArgumentParser(prog="bench", description="MonoInstance reference benchmark harness (CPU, small scenes).")
    sub = p.add_subparsers(dest="command", required=True)

    lst = sub.add_parser("list", help="list methods, tables and scenes")
    _add_tables_dir(lst)
    lst.set_defaults(func=cmd_list)

    config = sub.add_parser("config", help="a method's resolved config, checked against its typed config")
    config.add_argument("method")
    config.add_argument("--scale", default="small", choices=SCALES)
    config.add_argument("--set", nargs="+", default=[], metavar="KEY=VALUE", help="overrides (YAML values), as a table row's")
    config.set_defaults(func=cmd_config)

    scenes = sub.add_parser("scenes", help="scene datasets").add_subparsers(dest="scenes_command", required=True)
    make = scenes.add_parser("make", help="synthesise a recipe into a dataset folder in its on-disk format")
    make.add_argument("recipe", help="recipe YAML path, or a scene name from configs/scenes/")
    make.add_argument("--out", required=True, help="output dataset folder (written atomically)")
    make.add_argument("--scale", default="small", choices=SCALES)
    make.add_argument("--seed", type=int, default=None, help="override the recipe's seed")
    make.add_argument("--overwrite", action="store_true", help="replace an existing output folder")
    make.set_defaults(func=cmd_scenes_make)
    down = scenes.add_parser("downsize", help="a dataset folder at 1/FACTOR of its image size, in the same format (real data to CPU scale)")
    down.add_argument("src", help="dataset folder (ScanNet / Replica / DTU / LLFF layout)")
    down.add_argument("dst", help="output folder (written atomically)")
    down.add_argument("--factor", type=int, required=True)
    down.add_argument("--overwrite", action="store_true")
    down.set_defaults(func=cmd_scenes_downsize)
    card = scenes.add_parser("card", help="a scene's datasheet (prior errors by region, photometric content, capture) "
                                          "beside real-data anchors, as markdown")
    card.add_argument("target", metavar="RECIPE|DIR", nargs="+", help="recipe YAML path or scene name (synthesised in memory), "
                                                             "or a dataset folder with GT depth and instances; several: one summary "
                                                             "table of their headline fields")
    card.add_argument("--scale", default="small", choices=SCALES, help="recipe only")
    card.add_argument("--seed", type=int, default=None, help="recipe only: override the recipe's seed")
    card.add_argument("--out", default=None, metavar="FILE.md", help="also write the card there, and its plot as FILE.png")
    card.set_defaults(func=cmd_scenes_card)

    run = sub.add_parser("run", help="run a table's jobs and write its CSV, markdown and plot")
    run.add_argument("--table", required=True, nargs="+", help="table name(s) from configs/tables/, a path to your own table spec (.yaml), or 'all'")
    run.add_argument("--scale", default="small", choices=SCALES)
    run.add_argument("--rows", nargs="+", default=None, help="restrict to these row labels")
    run.add_argument("--scenes", nargs="+", default=None, help="restrict to these scenes")
    run.add_argument("--seeds", nargs="+", type=int, default=None, help="use these seeds instead of the table's")
    run.add_argument("--out", default=str(DEFAULT_OUT), help="results folder (a sub-folder per scale)")
    run.add_argument("--force", action="store_true", help="rerun jobs whose results exist")
    run.add_argument("--quiet", action="store_true", help="no progress bars")
    run.add_argument("--no-artifacts", action="store_true",
                     help="do not keep each job's mesh / uncertainty maps / renders under OUT/SCALE/artifacts/")
    _add_executor_flags(run)
    _add_tables_dir(run)
    run.set_defaults(func=cmd_run)

    reg = sub.add_parser("regress", help="compare a fresh run with the stored reference results; non-zero exit on regression")
    reg.add_argument("--table", required=True, nargs="+", help="table name(s) from configs/tables/, or 'all'")
    reg.add_argument("--scale", default="small", choices=SCALES)
    reg.add_argument("--out", default=str(DEFAULT_OUT / "regress"),
                     help="where the fresh run and the regression report go (a sub-folder per scale)")
    reg.add_argument("--reference-dir", default=str(REFERENCE_DIR), help="stored references (a sub-folder per scale)")
    reg.add_argument("--update-reference", action="store_true",
                     help="store this run as the new reference (refused if a job failed)")
    reg.add_argument("--rows", nargs="+", default=None, help="restrict to these row labels (the others count as not run)")
    reg.add_argument("--from-results", default=None, metavar="DIR",
                     help="no fresh run: use the results a `bench run --out DIR` stored (same job ids; "
                          "e.g. to store a reference from a finished run)")
    reg.add_argument("--quiet", action="store_true", help="no progress bars")
    _add_executor_flags(reg)
    _add_tables_dir(reg)
    reg.set_defaults(func=cmd_regress)

    rep = sub.add_parser("report", help="rebuild tables and one report.md from stored results")
    rep.add_argument("--table", nargs="+", default=None)
    rep.add_argument("--scale", default="small", choices=SCALES)
    rep.add_argument("--out", default=str(DEFAULT_OUT))
    _add_tables_dir(rep)
    rep.set_defaults(func=cmd_report)

    fit = sub.add_parser("fit", help="one method on your own dataset folder (any of the four formats); metrics where GT is present")
    fit.add_argument("method", help="a registered method (bench list)")
    fit.add_argument("path", help="dataset folder: MonoSDF ScanNet / Replica layout, IDR DTU layout or LLFF")
    fit.add_argument("--scale", default="small", choices=SCALES, help="the method's schedule preset")
    fit.add_argument("--set", nargs="+", default=None, metavar="KEY=VALUE", help="config overrides (YAML values)")
    fit.add_argument("--seed", type=int, default=0)
    fit.add_argument("--factor", type=int, default=None, help="LLFF: read images_FACTOR")
    fit.add_argument("--out", default=None, help="output folder (default results/runs/fit/METHOD-FOLDER-SCALE)")
    fit.set_defaults(func=cmd_fit)

    study = sub.add_parser("study", help="studies of one method on one scene").add_subparsers(dest="study_command", required=True)
    conv = study.add_parser("convergence", help="metrics, depth error, beta and losses along the schedule (dense snapshots), over seeds")
    conv.add_argument("method", help="a registered method (bench list)")
    conv.add_argument("scene", help="a scene recipe name or a dataset folder")
    conv.add_argument("--scale", default="small", choices=SCALES)
    conv.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    conv.add_argument("--snapshots", type=int, default=8, help="evenly spaced snapshots along the schedule")
    conv.add_argument("--exact-priors", nargs="?", const="both", default="none", choices=["both", "depth", "normal"],
                      metavar="{both,depth,normal}",
                      help="GT depth and GT normals as the priors (the ceiling they allow); 'depth' / 'normal': only that "
                           "one exact, the scene's other prior kept (which of the two a failure comes from)")
    conv.add_argument("--set", nargs="+", default=None, metavar="KEY=VALUE", help="config overrides (YAML values)")
    conv.add_argument("--sweep", default=None, metavar="KEY=V1,V2,...", help="repeat the study for each value of one config key")
    conv.add_argument("--workers", type=int, default=None, help="parallel runs (default: one single-threaded run per core)")
    conv.add_argument("--stop-at", type=float, default=1.0, metavar="FRACTION",
                      help="stop every run at this fraction of its schedule (same lr schedule): a cheap screen of the early phase")
    conv.add_argument("--out", default=None, help="output folder (default results/runs/studies/METHOD-SCENE-SCALE)")
    conv.set_defaults(func=cmd_study_convergence)
    return p


def _interrupt_on_sigterm() -> None:
    """SIGTERM (``kill``, a CI timeout) unwinds like Ctrl-C, so the executors stop their workers and no
    temporary folder is left behind (the main thread only)."""
    import signal
    import threading

    def handler(signum: int, frame: object) -> None:
        raise KeyboardInterrupt(f"signal {signum}")

    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, handler)


def main(argv: list[str] | None = None) -> int:
    try:  # Ctrl-C while the command starts (imports, parsing) ends as quietly as during its work
        return _run_command(argv)
    except KeyboardInterrupt as exc:
        print(f"interrupted ({str(exc) or 'Ctrl-C'}): running jobs stopped; finished results are kept", file=sys.stderr)
        return 130


def _run_command(argv: list[str] | None) -> int:
    """Parse ``argv`` and run the command; bad input and a closed output pipe as exit codes (module docstring)."""
    if argv is None:  # the console script, not a test calling main([...]): MKL's Intel (AVX-512 / AVX2) path on a non-Intel CPU
        from bench.mkl_dispatch import reexec_with_mkl_shim

        reexec_with_mkl_shim()  # re-executes this command once with the shim preloaded, or returns
    args = build_parser().parse_args(argv)
    if argv is None:
        _interrupt_on_sigterm()
    try:
        status = int(args.func(args) or 0)
        sys.stdout.flush()  # a closed pipe shows here, not in the interpreter's exit
        return status
    except BrokenPipeError:  # `bench list | head`: the reader has what it wanted
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no second error when Python flushes at exit
        return EXIT_BROKEN_PIPE
    except BenchInputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except FileExistsError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
