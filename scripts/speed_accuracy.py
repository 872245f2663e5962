"""Speed-accuracy curves of our estimator and its peers, and the table against match-score quality.

Regenerates ``docs/img/speed-accuracy-<preset>.png`` (success and median rotation error against
median time per frame, each estimator's confidence swept, one column per epsilon) and prints
its points with each one's time over ours (uniform, the same confidence and epsilon, this run);
with ``--prior-table``, instead the table of hypotheses and time of ours and
SupeRANSAC against the score AUC (uniform, PROSAC by score, guided / importance / AR by the
calibrated scores). Every estimator of a cell runs on the same frames, a frame's estimators one
after another, each the fastest of ``--repeats``; numba is warmed up first; the peers run on one
thread. Times are per frame, process CPU time by default (``--clock wall`` for wall time): compare
estimators within one run.

Usage::

    OMP_NUM_THREADS=1 python scripts/speed_accuracy.py [--preset default|random|hostile] [--n 500] [--frames 20]
    OMP_NUM_THREADS=1 python scripts/speed_accuracy.py --prior-table [--epsilons 0.5,0.8] [--frames 40]
"""

from __future__ import annotations

import argparse
import json
from dataclasses import asdict
from pathlib import Path

from tqdm import tqdm

from stereovo.benchmark import speed_accuracy as sa
from stereovo.benchmark.peers import set_clock, superansac_available

ROOT = Path(__file__).resolve().parents[1]


def floats(text: str) -> list[float]:
    try:
        return [float(x) for x in text.split(",") if x]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated numbers, got {text!r}") from None


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--preset", choices=sa.PRESETS, default="default", help="the simulator's outlier preset")
    parser.add_argument("--n", type=int, default=500, help="correspondences per frame")
    parser.add_argument("--frames", type=int, default=None, help="frames per cell (default 20; 40 for --prior-table)")
    parser.add_argument("--epsilons", type=floats, default=None, help="contaminations (default 0.5,0.8,0.9; "
                        "0.5,0.8 for --prior-table)")
    parser.add_argument("--confidences", type=floats, default=list(sa.CONFIDENCES), help="the swept confidences")
    parser.add_argument("--aucs", type=floats, default=list(sa.SCORE_AUCS), help="score AUCs of --prior-table")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--repeats", type=int, default=3, help="runs of each estimator on a frame, the fastest kept")
    parser.add_argument("--clock", choices=("cpu", "wall"), default="cpu",
                        help="process CPU time (default: every library here is single-threaded) or wall time")
    parser.add_argument("--prior-table", action="store_true", help="the score-quality table instead of the curves")
    parser.add_argument("--figure", default=None, help="figure path (default docs/img/speed-accuracy-<preset>.png)")
    parser.add_argument("--json", default=None, help="also write the points / rows as JSON here")
    parser.add_argument("--from-json", default=None, metavar="JSON",
                        help="redraw the figure from the points a run wrote with --json, measuring nothing")
    args = parser.parse_args()
    if args.from_json:
        points = [sa.CurvePoint(**row) for row in json.loads(Path(args.from_json).read_text())]
        figure = Path(args.figure or ROOT / "docs" / "img" / f"speed-accuracy-{args.preset}.png")
        frames = max(p.frames for p in points)
        sa.plot_curves(points, figure, f"N {args.n}, preset {args.preset}, {frames} frames per point, confidence swept "
                                       f"{min(p.setting for p in points)}-{max(p.setting for p in points)}, {args.clock} time")
        print(f"wrote {figure}")
        return 0
    if not superansac_available():
        print("note: SupeRANSAC is not installed (pip install -e '.[superansac]'); its rows are left out")
    set_clock(args.clock)
    sa.warm_up()
    if args.prior_table:
        epsilons, frames = args.epsilons or [0.5, 0.8], args.frames or 40
        with tqdm(total=len(epsilons) * len(args.aucs), desc="prior table", unit="cell") as bar:
            rows = sa.prior_table(args.n, epsilons, args.aucs, args.preset, frames, args.seed, args.repeats,
                                  progress=bar.update)
        print(f"N {args.n}, preset {args.preset}, {frames} frames a cell, confidence 0.99, "
              f"{args.clock} time, fastest of {args.repeats}")
        print(sa.prior_table_markdown(rows))
        result = rows
    else:
        epsilons, frames = args.epsilons or list(sa.EPSILONS), args.frames or 20
        with tqdm(total=len(epsilons), desc="speed-accuracy", unit="epsilon") as bar:
            points = sa.sweep(args.n, epsilons, args.preset, frames, args.seed, args.confidences, args.repeats,
                              progress=bar.update)
        figure = Path(args.figure or ROOT / "docs" / "img" / f"speed-accuracy-{args.preset}.png")
        sa.plot_curves(points, figure, f"N {args.n}, preset {args.preset}, {frames} frames per point, confidence swept "
                                       f"{min(args.confidences)}-{max(args.confidences)}, {args.clock} time")
        ours = {(p.epsilon, p.setting): p.median_ms for p in points if p.estimator == "ours"}
        print(f"{'eps':>4} {'estimator':<32} {'conf':>8} {'ms':>8} {'x ours':>7} {'success':>8} {'rot deg':>8} {'hyp':>7}")
        for p in points:
            ratio = p.median_ms / ours.get((p.epsilon, p.setting), float("nan"))
            print(f"{p.epsilon:>4.2f} {p.estimator:<32} {p.setting:>8.5g} {p.median_ms:>8.2f} {ratio:>7.2f} "
                  f"{p.success:>8.2f} {p.median_rot_deg:>8.4f} {p.median_hypotheses:>7.0f}")
        print(f"wrote {figure}")
        result = [asdict(p) for p in points]
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=1))
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
