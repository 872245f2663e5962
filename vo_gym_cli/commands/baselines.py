"""``vo-gym baselines``: every classical method on a benchmark grid of simulated frame pairs.

Writes to ``--out`` (default ``runs/baselines``):

- ``trials.csv``: one row per (frame, method); same ``--seed`` gives the same
  file apart from the wall-time column ``time_s`` (``--workers`` changes nothing);
- ``summary.csv`` / ``summary.md``: per-method table (success rate, median
  rotation and translation error, inlier precision and recall, hypotheses,
  point-hypothesis evaluations, median time) and breakdowns by epsilon and N;
- ``cells.csv``: the same statistics per (method, grid cell);
- ``claims.md``: the seed's qualitative claims checked one by one with these numbers;
- ``success_vs_epsilon.png``, ``hypotheses_vs_epsilon.png``, ``time_vs_n.png``, ``error_cdf.png``;
- ``run.json``: the settings, for ``scripts/make_baseline_report.py``;
- ``journal.csv`` and ``manifest.json``: every finished trial, appended as it finishes, and
  what the run computes (:mod:`stereovo.trials.store`). An interrupted run keeps its finished
  trials; ``--resume`` runs only the missing ones and ends with the files an uninterrupted run
  writes. ``--report-only DIR`` rebuilds the tables and plots from the stored trials.

Trials run on a backend (``--backend local``, the default: this process or a process pool of
``--workers``; ``--backend ray``: Ray tasks on a local instance of ``--workers`` CPUs, or on a
cluster with ``--address``). The rows never depend on the backend or the worker count.

The default grid (epsilon {0.2, 0.5, 0.8} x sigma 0.5 px x AUC {0.75, 0.9} x N {200, 500},
the simulator's outlier mix, 10 frames per cell = 120 frames, at most 2000 hypotheses)
takes one to two minutes on two cores; ``--full`` runs the whole grid (1296 cells,
many hours). ``--source rendered[:PRESET]`` runs the methods on rendered stereo images instead
(:mod:`vo_gym_cli.commands.baselines_images`).
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import re
import sys
import time
from pathlib import Path
from typing import Any


from vo_gym_cli.commands.arguments import (
    PRESETS,
    bounded_int,
    csv_list,
    max_count,
    output_path,
    parse_source,
    positive_int,
    seed as parse_seed,
)
from vo_gym_cli.commands.common import (
    RunStart,
    UsageError,
    check_output_dir,
    flag_error,
    interrupted_run,
    open_run_folder,
    stoppable,
    unread_option,
)

# stereovo.reporting.PLOT_FORMATS, spelled out so that building the parser imports no numerical code
# (a test checks that the two agree).
PLOT_FORMATS = ("png", "pdf", "svg")

MAX_WORKERS = 1024
"""The most worker processes (or local Ray CPUs) ``--workers`` asks for: more than any machine here has;
a larger count is a typo (``10**30`` overflowed the process pool's C int)."""


def add_backend_options(parser: argparse.ArgumentParser, what: str = "trials") -> None:
    """``--backend``, ``--workers``, ``--address``, ``--resume``, ``--overwrite``: shared by every grid command."""
    group = parser.add_argument_group("where the trials run and how a run survives")
    group.add_argument("--backend", choices=("local", "ray"), default="local",
                       help=f"local: {what} in this process or a process pool (default); ray: Ray tasks")
    group.add_argument("--workers", type=bounded_int("--workers", 1, MAX_WORKERS), default=None, metavar="N",
                       help="worker processes (local) or CPUs of the local Ray instance (default: the CPUs"
                            " available)")
    group.add_argument("--address", default=None, metavar="auto|HOST:PORT",
                       help="with --backend ray: join this Ray cluster instead of starting a local instance")
    group.add_argument("--resume", action="store_true",
                       help="complete the run in --out: run only the trials missing from its journal")
    group.add_argument("--overwrite", action="store_true", help="replace the run in a non-empty --out")


def backend_from_args(args: argparse.Namespace, workers: int):
    """The backend the options ask for; raises :class:`UsageError` naming the option."""
    from stereovo.trials import make_backend

    if args.address is not None and args.backend != "ray":
        raise UsageError(f"--address {args.address!r} needs --backend ray")
    try:
        return make_backend(args.backend, workers, args.address)
    except ValueError as err:
        raise UsageError(str(err)) from None


def add_parser(parser: argparse.ArgumentParser) -> None:
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    parser.epilog = (
        "default grid: epsilon 0.2,0.5,0.8 x sigma 0.5 x AUC 0.75,0.9 x N 200,500 x outliers mix,"
        " 10 frames per cell, max 2000 hypotheses (~2 min on 2 cores)\n"
        "--full:       epsilon 0.1..0.9 x sigma 0.25,0.5,1,2 x AUC 0.5,0.75,0.9 x N 100,500,1000 x"
        " outliers mix,random,stereo,moving, 10 frames per cell, core's hypothesis cap (hours)"
    )
    parser.add_argument("--methods", type=csv_list(str, "--methods"), default=None, metavar="A,B,...",
                        help="comma-separated methods (default: all; see --list-methods)")
    parser.add_argument("--list-methods", action="store_true", help="list the methods and exit")
    parser.add_argument("--full", action="store_true", help="run the issue's whole grid (hours)")
    parser.add_argument("--frames-per-cell", type=positive_int("--frames-per-cell"), default=None, metavar="F",
                        help="frames (seeds) per grid cell (default: 10)")
    parser.add_argument("--epsilons", type=csv_list(float, "--epsilons"), default=None, metavar="E,...",
                        help="override the grid's contamination values")
    parser.add_argument("--sigmas", type=csv_list(float, "--sigmas"), default=None, metavar="S,...",
                        help="override the grid's pixel noise values [px]")
    parser.add_argument("--aucs", type=csv_list(float, "--aucs"), default=None, metavar="A,...",
                        help="override the grid's match-score AUC values")
    parser.add_argument("--ns", type=csv_list(int, "--ns"), default=None, metavar="N,...",
                        help="override the grid's correspondence counts")
    parser.add_argument("--outlier-kinds", type=csv_list(str, "--outlier-kinds"), default=None, metavar="K,...",
                        help="override the grid's outlier kinds (mix, random, stereo, moving; hostile: the "
                             "simulator's hostile preset, match errors and Student-t noise the default grid never "
                             "makes)")
    parser.add_argument("--max-iterations", type=bounded_int("--max-iterations", 1, max_count), default=None,
                        metavar="K",
                        help="hypothesis cap for every method (default: 2000; --full: the core's default)")
    parser.add_argument("--preset", default=None, choices=list(PRESETS), help="motion preset (default: car)")
    parser.add_argument("--source", type=parse_source, default=None, metavar="rendered[:PRESET]",
                        help="run on rendered stereo images through the front end instead of the simulated grid "
                             "(needs the 'images' and 'render' extras; PRESET car or free, else --preset); "
                             "uses --methods, --max-iterations, --frames, --resolution, --preset, --seed, --out, "
                             "--overwrite, --no-plots, --format; no --resume (it keeps no journal) and no grid option")
    parser.add_argument("--frames", type=positive_int("--frames"), default=None,
                        help="with --source: rendered frame pairs (default: 40; the grid's are --frames-per-cell)")
    parser.add_argument("--resolution", default=None, choices=["kitti", "vga"],
                        help="with --source: image size, kitti (1241x376) or vga (640x480) (default: kitti)")
    parser.add_argument("--seed", type=parse_seed, default=0, help="base seed of frames and estimators (default: 0)")
    parser.add_argument("--out", type=output_path(), default=Path("runs/baselines"), help="output folder (default: runs/baselines)")
    parser.add_argument("--no-plots", action="store_true", help="skip the figures")
    parser.add_argument("--format", choices=PLOT_FORMATS, default="png", dest="plot_format",
                        help="file format of the figures (default: png)")
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    parser.add_argument("--report-only", type=Path, default=None, metavar="DIR",
                        help="rebuild the tables and plots of the run in DIR from its stored trials, in DIR (not"
                             " --out); runs nothing, so it takes --no-plots and --format only")
    parser.add_argument("--chunk", type=positive_int("--chunk"), default=1, metavar="K",
                        help="frames per backend task (default 1; larger cuts per-task overhead)")
    add_backend_options(parser, "frames")


def _json_safe(value: Any) -> Any:
    if isinstance(value, dict):
        return {str(k): _json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_safe(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def run(args: argparse.Namespace) -> int:
    return stoppable("baselines", lambda: _run(args))


GRID, IMAGES, REPORT = "grid", "images", "report"
# The options each of baselines' three runs reads (argparse dests); --no-progress and --list-methods
# serve all. An option typed on the command line (even at its default value) that the chosen run does
# not read is refused rather than silently ignored: --report-only DIR --out X would rewrite DIR and
# never make X.
READ_BY = {
    GRID: frozenset({"methods", "full", "frames_per_cell", "epsilons", "sigmas", "aucs", "ns", "outlier_kinds",
                     "max_iterations", "preset", "seed", "out", "no_plots", "plot_format", "chunk", "backend",
                     "workers", "address", "resume", "overwrite"}),
    IMAGES: frozenset({"source", "methods", "max_iterations", "frames", "resolution", "preset", "seed", "out",
                       "overwrite", "no_plots", "plot_format"}),
    REPORT: frozenset({"report_only", "no_plots", "plot_format"}),
}
_RUN_NAMES = {GRID: "the simulated grid", IMAGES: "--source rendered", REPORT: "--report-only"}


def check_options_apply(args: argparse.Namespace) -> None:
    """Raise a one-line UsageError naming the first given option that the chosen run (the grid,
    ``--source`` or ``--report-only``) does not read, its value, the run(s) that read it and why not here."""
    run = REPORT if args.report_only is not None else IMAGES if args.source is not None else GRID
    unread = unread_option(args, add_parser, READ_BY, run)
    if unread is None:
        return
    given, dest, owners = unread
    if run == REPORT and dest == "source":  # the option selects a run of its own
        raise UsageError(f"--report-only and {given} exclude each other: --report-only rebuilds the report of the "
                         "run in DIR from the trials stored there; give one")
    here = {GRID: "to the simulated grid", IMAGES: f"with --source {args.source}",
            REPORT: "with --report-only"}[run]
    if run == REPORT:
        why = "it rebuilds the report of the run in DIR, in DIR, from the trials stored there"
    elif dest == "resume":
        why = "it keeps no journal to resume from; --overwrite replaces the run"
    elif dest in ("chunk", "backend", "workers", "address"):
        why = "it runs in this process"
    elif run == IMAGES:
        why = "the contamination, noise and matches are the rendering's and the front end's"
    elif dest == "frames":
        why = "the grid's frames are --frames-per-cell"
    else:
        why = ""
    raise UsageError(f"{given} applies to {' and '.join(_RUN_NAMES[r] for r in owners)}, not {here}"
                     + (f" ({why})" if why else ""))


def _json_object(path: Path, what: str) -> dict[str, Any]:
    """A JSON object file of a run folder; UsageError naming the file and what is wrong."""
    from stereovo.trials.store import JournalError, read_manifest

    try:
        data = read_manifest(path)
    except JournalError as err:
        raise UsageError(f"--report-only {str(path.parent)!r}: {path.name} is not the {what} of a run"
                         f" ({err.detail})") from None
    return data


def _stored_rows(folder: Path) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """Rows and settings of a run folder: ``trials.csv`` of a finished run, else its journal.

    Everything is read and checked here, before anything is written (UsageError naming the file)."""
    from stereovo import benchmark as bm
    from stereovo.benchmark.aggregation import TrialsFileError
    from stereovo.trials.store import JOURNAL, MANIFEST, JournalError, read_journal

    where = f"--report-only {str(folder)!r}"
    for name in ("run.json", MANIFEST, JOURNAL, "trials.csv"):
        if (folder / name).is_dir():
            raise UsageError(f"{where}: {name} is a directory, not a file of a run")
    settings: dict[str, Any] = {}
    if (folder / "run.json").is_file():
        settings = _json_object(folder / "run.json", "settings")
    journal = folder / JOURNAL
    if journal.is_file():
        try:
            done = read_journal(journal, bm.parse_trial_value, bm.TRIAL_COLUMNS)
        except JournalError as err:
            raise UsageError(f"{where}: {err}") from None
        rows = [row for key in sorted(done) for row in done[key]]
        if not settings and (folder / MANIFEST).is_file():
            manifest = _json_object(folder / MANIFEST, "manifest")
            axes = manifest.get("grid_axes")
            try:
                if not isinstance(axes, dict):
                    raise ValueError(f"grid_axes is {type(axes).__name__ if axes is not None else 'missing'},"
                                     " not an object")
                grid = bm.BenchmarkGrid(**{str(k): tuple(v) if isinstance(v, list) else v for k, v in axes.items()})
                settings = {"grid": grid.describe(), "grid_axes": axes, "max_iterations": grid.max_iterations,
                            "methods": manifest.get("methods"), "seed": manifest.get("seed")}
            except (TypeError, ValueError) as err:
                raise UsageError(f"{where}: {MANIFEST} is not the manifest of a run ({err})") from None
            settings["n_trials_done"] = len(done)
        return rows, settings
    if (folder / "trials.csv").is_file():
        try:
            return bm.read_trials_csv(folder / "trials.csv"), settings
        except TrialsFileError as err:
            raise UsageError(f"{where}: {err}") from None
    raise UsageError(f"{where}: no trials.csv or {JOURNAL} there")


def _report_only(args: argparse.Namespace) -> int:
    from stereovo import benchmark as bm

    folder: Path = args.report_only
    if not folder.is_dir():
        raise UsageError(f"--report-only {str(folder)!r} is not a directory")
    check_output_dir(folder, "--report-only")
    rows, settings = _stored_rows(folder)
    if not rows:
        raise UsageError(f"--report-only {str(folder)!r}: no finished trials stored yet")
    summary, claims = bm.write_outputs(rows, folder, settings, plots=not args.no_plots, plot_format=args.plot_format)
    n_frames = len({r["trial"] for r in rows})
    print(f"vo-gym baselines: rebuilt the report of {folder} from {n_frames} stored frames ({len(rows)} rows)\n")
    print(bm.overall_table(summary))
    print(f"\n  wrote {folder}/: trials.csv, summary.csv, cells.csv, summary.md, claims.md"
          + ("" if args.no_plots else ", " + ", ".join(bm.plot_files(args.plot_format))))
    return 0


def _run(args: argparse.Namespace) -> int:
    from stereovo import benchmark as bm

    if args.list_methods:
        for name in bm.benchmark_methods():
            print(f"{name:<22} {bm.describe_method(name)}")
        return 0
    check_options_apply(args)
    if args.report_only is not None:
        return _report_only(args)
    if args.source is not None:
        from vo_gym_cli.commands.baselines_images import run_on_images  # imports this module

        return run_on_images(args)

    base = bm.FULL_GRID if args.full else bm.DEFAULT_GRID
    # Each axis alone first, so that a value out of range is named by its flag, and each value of a
    # list alone, so that the message shows the one refused (the grid's own shows the whole axis).
    for flag, axis, value in (("--epsilons", "epsilons", args.epsilons), ("--sigmas", "noise_sigmas", args.sigmas),
                              ("--aucs", "score_aucs", args.aucs), ("--ns", "ns", args.ns),
                              ("--outlier-kinds", "outlier_kinds", args.outlier_kinds),
                              ("--frames-per-cell", "frames_per_cell", args.frames_per_cell),
                              ("--max-iterations", "max_iterations", args.max_iterations)):
        for part in ([[v] for v in value] if isinstance(value, list) else [value]) if value is not None else []:
            try:
                base.with_axes(**{axis: part})
            except ValueError as err:
                error = flag_error(flag, err)
                if isinstance(part, list):
                    shown = f"{part[0]:g}" if isinstance(part[0], float) else str(part[0])
                    error = UsageError(re.sub(r", got .*$", f", got {shown}", str(error)))
                raise error from None
    try:
        grid = base.with_axes(
            epsilons=args.epsilons, noise_sigmas=args.sigmas, score_aucs=args.aucs, ns=args.ns,
            outlier_kinds=args.outlier_kinds, frames_per_cell=args.frames_per_cell,
            max_iterations=args.max_iterations, preset=args.preset,
        )
    except ValueError as err:
        raise UsageError(str(err)) from None
    options = {} if grid.max_iterations is None else {"max_iterations": grid.max_iterations}
    try:
        estimators = bm.classical_estimators(args.methods, **options)
    except ValueError as err:
        raise UsageError(f"--methods: {err}") from None
    if args.address is not None and args.backend != "ray":
        raise UsageError(f"--address {args.address!r} needs --backend ray")
    from stereovo.trials import TrialJournal

    start = RunStart(args.out)
    out = open_run_folder(args)  # before any computing
    journal = TrialJournal(out, bm.TRIAL_COLUMNS, bm.parse_trial_value)
    try:
        return _benchmark(args, grid, estimators, options, out, journal)
    except (UsageError, ValueError, TypeError, ModuleNotFoundError):
        journal.close()
        if not args.resume and not journal.read():  # nothing finished: leave --out as it was
            start.undo()
        raise


def _benchmark(args, grid, estimators, options, out, journal) -> int:
    from stereovo import benchmark as bm
    from stereovo.trials import RunInterrupted
    from stereovo.trials.store import RunFolderError, atomic_write_text

    workers = args.workers or bm.default_workers()
    trials = grid.trials()
    names = [name for name, _ in estimators]
    manifest = {"command": "baselines", "grid_axes": grid.as_dict(), "methods": names, "seed": args.seed,
                "options": _json_safe(options)}
    try:
        done = journal.open(manifest, resume=args.resume, keys=range(len(trials)))
    except RunFolderError as err:
        raise UsageError(str(err)) from None
    try:
        print(f"vo-gym baselines: {grid.describe()}")
        backend = backend_from_args(args, workers)
        print(f"  {len(names)} methods: {', '.join(names)}; seed {args.seed}; {backend.describe()}", flush=True)
        if done:
            print(f"  resuming: {len(done)} of {len(trials)} frames already in {out}/journal.csv", flush=True)
        if len(done) < len(trials):
            print("  warming up: every method once per worker before timing (compiles the kernels on a first"
                  " run)", flush=True)
        start = time.perf_counter()
        try:
            bm.run_benchmark(trials, estimators, seed=args.seed, workers=workers, progress=not args.no_progress,
                             desc="baselines", backend=backend, journal=journal, done=done, chunk=args.chunk)
        finally:
            backend.close()
        wall = time.perf_counter() - start
    except (RunInterrupted, KeyboardInterrupt) as stop:
        return interrupted_run(journal, stop, len(trials), out)
    journal.close()
    # The final files come from the journal, so a resumed run writes exactly what an uninterrupted one does.
    stored = journal.read()
    rows = [row for t in trials for row in stored[t.index]]

    settings = {
        "grid": grid.describe(),
        "grid_axes": grid.as_dict(),
        "max_iterations": grid.max_iterations,
        "methods": names,
        "method_descriptions": {n: bm.describe_method(n) for n in names},
        "seed": args.seed,
        "workers": workers,
        "backend": args.backend,
        "full": bool(args.full),
        "n_trials": len(trials),
        "n_rows": len(rows),
        "n_resumed": len(done),
        "wall_s": round(wall, 1),
        "machine": f"{platform.machine()}, {bm.default_workers()} CPUs available, Python {platform.python_version()}",
    }
    summary, claims = bm.write_outputs(rows, out, settings, plots=not args.no_plots, plot_format=args.plot_format)
    atomic_write_text(out / "run.json", json.dumps(_json_safe(settings), indent=2) + "\n")

    print(f"\n{len(trials)} frames x {len(names)} methods in {wall:.1f} s"
          + (f" ({len(done)} frames resumed)" if done else "") + "\n")
    print(bm.overall_table(summary))
    print()
    width = max(len(c.key) for c in claims)
    print("claims of the papers, checked on these frames:")
    for c in claims:
        print(f"  {c.key:<{width}}  {c.verdict}")
    print(f"  {out / 'claims.md'} states each claim, its source and the numbers behind each verdict")
    errors = sum(s.get("n_errors", 0) for s in summary.overall.values())
    if errors:
        print(f"  warning: {errors} estimator call(s) raised; see the status column of trials.csv", file=sys.stderr)
    files = "trials.csv, summary.csv, cells.csv, summary.md, claims.md, run.json"
    if not args.no_plots:
        files += ", " + ", ".join(bm.plot_files(args.plot_format))
    print(f"\n  wrote {out}/: {files}")
    return 0
