"""``vo-gym sweep CONFIG.yaml``: hyperparameter sweeps of the NG-RANSAC and PPO trainers on Ray Tune.

The sweep file (see :mod:`agents.sweep_config`) holds the search space (grid and random axes, seeds
as an axis), the metric (held-out success at a budget) and the scheduler (ASHA early stopping
by default). Trials run side by side on a local Ray instance of ``--workers`` CPUs, or on a
cluster with ``--address``.

Writes to ``--out`` (default ``runs/sweep/<name>``): ``tune/`` (Tune's experiment: every
trial's reports and checkpoints), ``results.csv`` / ``results.md`` (a row per trial, best
first), ``metric_over_training.png``, ``best.json`` (the best trial's full trainer config and
metric) and ``best_checkpoint/``. After an interrupt, ``--resume`` restores the experiment and
completes it from the trials' last checkpoints.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from vo_gym_cli.commands.arguments import output_path, positive_int
from vo_gym_cli.commands.common import EXIT_INTERRUPTED, UsageError, check_output_dir, guarded, require_extras


def add_parser(parser: argparse.ArgumentParser) -> None:
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    parser.epilog = "example: vo-gym sweep configs/sweeps/example.yaml (a few minutes on 2 cores)"
    parser.add_argument("config", type=Path, help="sweep file (YAML): algo, fixed, space, metric, scheduler")
    parser.add_argument("--out", type=output_path(), default=None, help="output folder (default: runs/sweep/<name>)")
    parser.add_argument("--workers", type=positive_int("--workers"), default=None, metavar="N",
                        help="CPUs of the local Ray instance = trials side by side (default: the CPUs available)")
    parser.add_argument("--address", default=None, metavar="auto|HOST:PORT",
                        help="join this Ray cluster instead of starting a local instance")
    parser.add_argument("--resume", action="store_true", help="restore the interrupted sweep in --out and complete it")
    parser.add_argument("--overwrite", action="store_true", help="replace the sweep in a non-empty --out")
    talk = parser.add_mutually_exclusive_group()
    talk.add_argument("--verbose", action="store_true",
                      help="Ray's and Tune's own console output: the per-trial table and the workers' logs"
                           " (default: one progress bar over the trials)")
    talk.add_argument("--quiet", action="store_true", help="no progress bar either")


def run(args: argparse.Namespace) -> int:
    return guarded("sweep", lambda: _run(args))


def _run(args: argparse.Namespace) -> int:
    require_extras("yaml", "ray", "torch")
    from agents.sweep import run_sweep, write_sweep_outputs
    from agents.sweep_config import load_sweep
    from stereovo.benchmark import default_workers
    from stereovo.trials import RunFolderError, prepare_run_folder

    try:
        spec = load_sweep(args.config)
    except (FileNotFoundError, ValueError) as err:
        raise UsageError(str(err)) from None
    out = args.out if args.out is not None else Path("runs/sweep") / spec.name
    try:
        prepare_run_folder(out, resume=args.resume, overwrite=args.overwrite)
    except RunFolderError as err:
        raise UsageError(str(err)) from None
    if args.overwrite and (out / "tune").exists():
        import shutil

        shutil.rmtree(out / "tune")
    check_output_dir(out)
    workers = args.workers or default_workers()
    where = f"cluster {args.address}" if args.address else f"a local Ray instance with {workers} CPU(s)"
    print(f"vo-gym sweep: {spec.name} ({spec.algo}), {spec.metric.describe()}; {spec.scheduler['type']} scheduler;"
          f" report every {spec.report_every} of {spec.total_steps} steps; {where}", flush=True)
    try:
        outcome = run_sweep(spec, out, workers=None if args.address else workers, address=args.address,
                            resume=args.resume, verbose=1 if args.verbose else 0, progress=not args.quiet)
    except ValueError as err:
        raise UsageError(str(err)) from None
    except KeyboardInterrupt:
        print(f"interrupted: sweep state saved in {out}; rerun with --resume", file=sys.stderr)
        return EXIT_INTERRUPTED
    paths = write_sweep_outputs(spec, outcome, out)
    if not outcome.complete:
        done = sum(1 for t in outcome.trials if t["history"])
        print(f"interrupted: {done} of {len(outcome.trials)} trials saved in {out}; rerun with --resume",
              file=sys.stderr)
        return EXIT_INTERRUPTED
    print((out / "results.md").read_text())
    if outcome.errors:
        print(f"  warning: {outcome.errors} trial(s) raised; see results.csv and {out}/tune", file=sys.stderr)
    print(f"wrote {out}/: {', '.join(p.name for p in paths)}")
    return 0
