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
- ``run.json``: the settings, for ``scripts/make_baseline_report.py``.

The default grid (epsilon {0.2, 0.5, 0.8} x sigma 0.5 px x AUC {0.75, 0.9} x N {200, 500},
the simulator's outlier mix, 10 frames per cell = 120 frames, at most 2000 hypotheses)
takes one to two minutes on two cores; ``--full`` runs the issue's whole grid (1296 cells,
many hours).
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import sys
import time
from pathlib import Path
from typing import Any, Callable


def _csv_list(kind: Callable[[str], Any], name: str) -> Callable[[str], list[Any]]:
    def parse(text: str) -> list[Any]:
        items = [t.strip() for t in text.split(",") if t.strip()]
        if not items:
            raise argparse.ArgumentTypeError(f"{name} needs at least one value")
        try:
            return [kind(t) for t in items]
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} {text!r}: expected comma-separated {kind.__name__} values") from None

    return parse


def _positive_int(name: str) -> Callable[[str], int]:
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} {text!r} is not an integer") from None
        if value < 1:
            raise argparse.ArgumentTypeError(f"{name} must be >= 1, got {value}")
        return value

    return parse


def _seed(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--seed {text!r} is not an integer") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"--seed must be >= 0, got {value}")
    return value


def add_parser(parser: argparse.ArgumentParser) -> None:
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    parser.epilog = (
        "default grid: epsilon 0.2,0.5,0.8 x sigma 0.5 x AUC 0.75,0.9 x N 200,500 x outliers mix,"
        " 10 frames per cell, max 2000 hypotheses (~2 min on 2 cores)\n"
        "--full:       epsilon 0.1..0.9 x sigma 0.25,0.5,1,2 x AUC 0.5,0.75,0.9 x N 100,500,1000 x"
        " outliers mix,random,stereo,moving, 10 frames per cell, core's hypothesis cap (hours)"
    )
    parser.add_argument("--methods", type=_csv_list(str, "--methods"), default=None, metavar="A,B,...",
                        help="comma-separated methods (default: all; see --list-methods)")
    parser.add_argument("--list-methods", action="store_true", help="list the methods and exit")
    parser.add_argument("--full", action="store_true", help="run the issue's whole grid (hours)")
    parser.add_argument("--frames-per-cell", type=_positive_int("--frames-per-cell"), default=None, metavar="F",
                        help="frames (seeds) per grid cell (default: 10)")
    parser.add_argument("--epsilons", type=_csv_list(float, "--epsilons"), default=None, metavar="E,...",
                        help="override the grid's contamination values")
    parser.add_argument("--sigmas", type=_csv_list(float, "--sigmas"), default=None, metavar="S,...",
                        help="override the grid's pixel noise values [px]")
    parser.add_argument("--aucs", type=_csv_list(float, "--aucs"), default=None, metavar="A,...",
                        help="override the grid's match-score AUC values")
    parser.add_argument("--ns", type=_csv_list(int, "--ns"), default=None, metavar="N,...",
                        help="override the grid's correspondence counts")
    parser.add_argument("--outlier-kinds", type=_csv_list(str, "--outlier-kinds"), default=None, metavar="K,...",
                        help="override the grid's outlier kinds (mix, random, stereo, moving)")
    parser.add_argument("--max-iterations", type=_positive_int("--max-iterations"), default=None, metavar="K",
                        help="hypothesis cap for every method (default: 2000; --full: the core's default)")
    parser.add_argument("--preset", default="car", choices=["car", "free"], help="motion preset (default: car)")
    parser.add_argument("--workers", type=_positive_int("--workers"), default=None, metavar="N",
                        help="worker processes (default: the CPUs available)")
    parser.add_argument("--seed", type=_seed, default=0, help="base seed of frames and estimators (default: 0)")
    parser.add_argument("--out", type=Path, default=Path("runs/baselines"), help="output folder (default: runs/baselines)")
    parser.add_argument("--no-plots", action="store_true", help="skip the PNG figures")
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")


def _error(message: str) -> int:
    print(f"vo-gym baselines: error: {message}", file=sys.stderr)
    return 2


def _json_safe(value: Any) -> Any:
    if isinstance(value, dict):
        return {str(k): _json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_safe(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def run(args: argparse.Namespace) -> int:
    from stereovo import benchmark as bm

    if args.list_methods:
        for name in bm.benchmark_methods():
            print(f"{name:<22} {bm.describe_method(name)}")
        return 0

    base = bm.FULL_GRID if args.full else bm.DEFAULT_GRID
    try:
        grid = base.with_axes(
            epsilons=args.epsilons, noise_sigmas=args.sigmas, score_aucs=args.aucs, ns=args.ns,
            outlier_kinds=args.outlier_kinds, frames_per_cell=args.frames_per_cell,
            max_iterations=args.max_iterations, preset=args.preset,
        )
    except ValueError as err:
        return _error(str(err))
    options = {} if grid.max_iterations is None else {"max_iterations": grid.max_iterations}
    try:
        estimators = bm.classical_estimators(args.methods, **options)
    except ValueError as err:
        return _error(f"--methods: {err}")
    workers = args.workers or bm.default_workers()
    trials = grid.trials()
    names = [name for name, _ in estimators]

    print(f"vo-gym baselines: {grid.describe()}")
    print(f"  {len(names)} methods: {', '.join(names)}; seed {args.seed}; {workers} worker(s)")
    start = time.perf_counter()
    rows = bm.run_benchmark(trials, estimators, seed=args.seed, workers=workers,
                            progress=not args.no_progress, desc="baselines")
    wall = time.perf_counter() - start

    settings = {
        "grid": grid.describe(),
        "grid_axes": grid.as_dict(),
        "max_iterations": grid.max_iterations,
        "methods": names,
        "method_descriptions": {n: bm.describe_method(n) for n in names},
        "seed": args.seed,
        "workers": workers,
        "full": bool(args.full),
        "n_trials": len(trials),
        "n_rows": len(rows),
        "wall_s": round(wall, 1),
        "machine": f"{platform.machine()}, {bm.default_workers()} CPUs available, Python {platform.python_version()}",
    }
    out: Path = args.out
    summary, claims = bm.write_outputs(rows, out, settings, plots=not args.no_plots)
    (out / "run.json").write_text(json.dumps(_json_safe(settings), indent=2) + "\n")

    print(f"\n{len(trials)} frames x {len(names)} methods in {wall:.1f} s\n")
    print(bm.overall_table(summary))
    print()
    width = max(len(c.key) for c in claims)
    for c in claims:
        print(f"  {c.key:<{width}}  {c.verdict}")
    errors = sum(s.get("n_errors", 0) for s in summary.overall.values())
    if errors:
        print(f"  warning: {errors} estimator call(s) raised; see the status column of trials.csv", file=sys.stderr)
    files = "trials.csv, summary.csv, cells.csv, summary.md, claims.md, run.json"
    if not args.no_plots:
        files += ", " + ", ".join(bm.PLOT_FILES)
    print(f"\n  wrote {out}/: {files}")
    return 0
