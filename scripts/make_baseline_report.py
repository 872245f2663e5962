#!/usr/bin/env python
"""Regenerate ``docs/baselines.md`` from a ``vo-gym baselines`` run.

Usage::

    vo-gym baselines --out runs/baselines
    python scripts/make_baseline_report.py --from runs/baselines

``--name baselines-full`` writes ``docs/baselines-full.md`` and ``docs/img/baselines-full/``
instead (the report of the full grid, beside the default grid's). Without ``--from`` the default grid is run first (into ``runs/baselines``). The summary and the claim checks are
recomputed from ``trials.csv`` (the run's only source of truth), the run's
figures are copied to ``docs/img/baselines/`` (redrawn from the CSV when the
run has none, or with ``--redraw``), and ``docs/baselines.md`` is rewritten
(:func:`stereovo.benchmark.baseline_report.write_baseline_report`).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from stereovo.benchmark.baseline_report import REPORT_NAME, write_baseline_report

REPO = Path(__file__).resolve().parent.parent


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--from", dest="run_dir", type=Path, default=None,
                        help="a `vo-gym baselines` output folder (default: run the default grid first)")
    parser.add_argument("--docs", type=Path, default=REPO / "docs", help="docs folder (default: the repo's docs/)")
    parser.add_argument("--out", type=Path, default=Path("runs/baselines"),
                        help="where to run the default grid when --from is not given (default: runs/baselines)")
    parser.add_argument("--name", default=REPORT_NAME,
                        help="report name: docs/NAME.md and docs/img/NAME/ (default: baselines)")
    parser.add_argument("--redraw", action="store_true", help="draw the figures again from trials.csv instead of copying them")
    parser.add_argument("--workers", type=int, default=None, help="worker processes for that run")
    parser.add_argument("--seed", type=int, default=0, help="seed for that run (default: 0)")
    args = parser.parse_args(argv)

    run_dir = args.run_dir
    if run_dir is None:
        from vo_gym_cli.main import main as vo_gym

        cli = ["baselines", "--out", str(args.out), "--seed", str(args.seed)]
        if args.workers:
            cli += ["--workers", str(args.workers)]
        code = vo_gym(cli)
        if code:
            return code
        run_dir = args.out
    try:
        path = write_baseline_report(run_dir, args.docs, redraw=args.redraw, name=args.name)
    except FileNotFoundError as err:
        print(f"make_baseline_report: error: {err}", file=sys.stderr)
        return 2
    print(f"wrote {path} and {args.docs / 'img' / args.name}/")
    return 0


if __name__ == "__main__":
    sys.exit(main())
