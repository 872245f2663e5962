"""Count confidently wrong estimates: "ok" with a rotation error above 10 deg or a translation error
above 1 m, for every registered method on hostile frames (or another outliers preset).

    python scripts/bench_confident_errors.py --frames 10000 --methods probabilistic
    python scripts/bench_confident_errors.py --frames 600          # every method
    python scripts/bench_confident_errors.py --frames 5000 --first 5000 --methods mlesac   # the second half

Frames cycle through the cells N 200 / 500 / 1000 x eps 0.2, 0.5, 0.8, 0.9 (seeded by their index,
so every method sees the same frames). A method that needs sampling input gets the calibrated
scores in the form the benchmark gives them (``METHOD_INPUTS``). Prints, per method, the frames, successes, confidently wrong
estimates and failed statuses, with a progress bar; ``--out`` writes the table as CSV (success as the
fraction printed, the other columns as counts).
"""

from __future__ import annotations

import argparse
import csv
import itertools

import numpy as np
from tqdm import tqdm

from stereovo import estimate_motion
from stereovo.benchmark.runner import METHOD_INPUTS, score_inputs
from stereovo.estimation import available_methods, method_spec
from stereovo.metrics import frame_metrics
from stereovo.simulation import OUTLIER_PRESETS, SimulationConfig, simulate_frame

CELLS = list(itertools.product((200, 500, 1000), (0.2, 0.5, 0.8, 0.9)))
ABSURD_ROT_DEG, ABSURD_TRANS_M = 10.0, 1.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=600, help="frames per method (default 600)")
    parser.add_argument("--methods", default="all", help="comma-separated names, or 'all' (default)")
    parser.add_argument("--outliers", default="hostile", choices=sorted(OUTLIER_PRESETS))
    parser.add_argument("--first", type=int, default=0,
                        help="index of the first frame of the stream (default 0): split a long run into parts")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", help="CSV of the table")
    args = parser.parse_args()
    if args.frames < 1:
        parser.error(f"--frames must be >= 1, got {args.frames}")
    if args.first < 0:
        parser.error(f"--first must be >= 0, got {args.first}")
    methods = sorted(available_methods()) if args.methods == "all" else args.methods.split(",")
    for name in methods:
        method_spec(name)  # an unknown name fails here, before any work
    rows = []
    print(f"{'method':28s} {'frames':>7s} {'success':>8s} {'wrong ok':>9s} {'failed':>7s}")
    for method in methods:
        success = wrong = failed = 0
        for i in tqdm(range(args.first, args.first + args.frames), desc=method, leave=False):
            n, eps = CELLS[i % len(CELLS)]
            frame = simulate_frame(
                SimulationConfig(n_correspondences=n, outlier_ratio=eps, outliers=args.outliers), args.seed * 10**7 + i
            )
            given = score_inputs(frame, METHOD_INPUTS.get(method))
            est = estimate_motion(frame.prev, frame.curr, frame.camera, method=method, rng=i, **given)
            errors = frame_metrics(est, frame.truth)
            success += errors.success
            failed += not est.ok
            wrong += est.ok and (errors.rot_err_deg > ABSURD_ROT_DEG or errors.trans_err_m > ABSURD_TRANS_M)
        rows.append(dict(method=method, frames=args.frames, success=success / args.frames, wrong_ok=wrong, failed=failed))
        print(f"{method:28s} {args.frames:7d} {success / args.frames:8.3f} {wrong:9d} {failed:7d}", flush=True)
    if args.out:
        with open(args.out, "w", newline="") as handle:
            writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
            writer.writeheader()
            writer.writerows(rows)


if __name__ == "__main__":
    main()
