"""``vo-gym bench``: time the estimator core against optional peers on identical frames.

For every (N, epsilon) cell the same simulated frames go to our core and, when
the ``peers`` extra is installed, to OpenCV's ``solvePnPRansac`` and PoseLib's
``estimate_absolute_pose``, and with the ``superansac`` extra to SupeRANSAC's PnP
(3-D points triangulated at k-1, left-image pixels at k; optionally its 3-D-3-D
rigid transform). The runners are :mod:`stereovo.benchmark.peers`. It prints per-frame median time, hypotheses per second, success rate
and median rotation error, and the ratio of our median time to each peer's.
Every estimator is called once on a frame of its own before anything is timed (:func:`warm_up`).
Speed is measured here, never asserted in tests.
"""

from __future__ import annotations

import argparse
import os
from typing import Callable

import numpy as np

from vo_gym_cli.commands.arguments import (
    bounded_int,
    csv_list,
    finite_float,
    max_correspondences,
    max_frames,
    method_name,
    output_path,
)
from vo_gym_cli.commands.common import UsageError, check_output_file, score_inputs
from vo_gym_cli.commands.arguments import seed as seed_type

DEFAULT_NS = (200, 500, 1000)
DEFAULT_EPSILONS = (0.2, 0.5, 0.8)
# Outlier kinds (random, stereo, moving-object weights). "random" is the default because a random
# mismatch corrupts the left pixel at k, which every estimator here uses, so the peers and we face
# the same contamination. A stereo mismatch at k corrupts only the right pixel at k: an outlier for
# our two-image core but invisible to a one-image PnP peer, which then faces a lower epsilon.
# "hostile": the simulator's hostile preset (SimulationConfig(outliers="hostile")): the match errors of
# real front ends, several of which leave rows without a depth (peers get the rows with one at k-1).
BENCH_OUTLIER_MIXES = {"random": (1.0, 0.0, 0.0), "random+stereo": (0.8, 0.2, 0.0), "hostile": None}


PEER_SEED_MAX = 2**31 - 1
"""The largest seed the peers take (``cv2.setRNGSeed`` refuses what does not fit a C int)."""


def _runners(args: argparse.Namespace) -> dict[str, Callable]:
    """Our method and, unless ``--no-peers``, every installed peer (one line for each missing one)."""
    from stereovo.benchmark import peers

    inputs = score_inputs(args.method)  # PROSAC-style methods get the scores' order, guided MLESAC the probabilities
    sampling = "prosac" if "order_fn" in inputs else "guided" if "priors_fn" in inputs else "uniform"
    runners: dict[str, Callable] = {f"ours:{args.method}": peers.ours(args.method, sampling)}
    if args.no_peers:
        return runners
    sampler = args.superansac_sampler or "uniform"
    factories = [("opencv", peers.opencv, "peers"), ("poselib", peers.poselib, "peers"),
                 (f"superansac:{sampler}", lambda: peers.superansac(sampler), "superansac")]
    if args.superansac_rigid:
        factories.append((f"superansac-rigid:{sampler}", lambda: peers.superansac(sampler, rigid=True), "superansac"))
    for name, factory, extra in factories:
        runner = factory()
        if runner is None:
            print(f"note: {name.split(':')[0]} is not installed (pip install -e '.[{extra}]'); skipping it")
        else:
            runners[name] = runner
    return runners


def add_parser(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--ns", type=csv_list(bounded_int("--ns", 3, max_correspondences), "--ns"),
                        default=list(DEFAULT_NS),
                        metavar="N,...", help="comma-separated correspondence counts N (each >= 3)")
    parser.add_argument("--epsilons", type=csv_list(finite_float("--epsilons", 0.0, 1.0, high_open=True), "--epsilons"),
                        default=list(DEFAULT_EPSILONS), metavar="E,...",
                        help="comma-separated contaminations, each in [0, 1)")
    parser.add_argument(
        "--frames", type=bounded_int("--frames", 1, max_frames), default=100,
        help="frames per (N, epsilon) cell (a median rotation error over fewer frames can tie by chance)",
    )
    parser.add_argument("--method", type=method_name("--method"), default="probabilistic",
                        help="our method to time (PROSAC-style methods get the match scores' order, "
                             "guided MLESAC the scores calibrated to inlier probabilities)")
    parser.add_argument(
        "--outliers", choices=sorted(BENCH_OUTLIER_MIXES), default="random",
        help="outlier kinds: random mismatches (same contamination for every estimator), a stereo blend, "
             "or the simulator's hostile preset (independent left/right mismatches, duplicates, far clutter, "
             "repetitive texture, Student-t noise)",
    )
    parser.add_argument("--noise", type=finite_float("--noise", 1e-3, 1e3), default=0.5,
                        help="pixel noise sigma (px), in [0.001, 1000]")
    parser.add_argument("--seed", type=seed_type, default=0, help="seed of the frames and of the estimators (>= 0)")
    parser.add_argument("--no-peers", action="store_true", help="skip OpenCV, PoseLib and SupeRANSAC even if installed")
    parser.add_argument("--superansac-sampler", choices=("uniform", "prosac", "importance", "ar"), default=None,
                        help="SupeRANSAC's sampler (the 'superansac' extra, CPython 3.11 on Linux); importance and ar "
                             "get the scores calibrated to inlier probabilities, prosac the matches by score "
                             "(default: uniform; not with --no-peers)")
    parser.add_argument("--superansac-rigid", action="store_true",
                        help="also run SupeRANSAC's 3-D-3-D rigid transform on the points triangulated in both frames"
                             " (not with --no-peers)")
    parser.add_argument("--out", type=output_path("--out", str), default=None, metavar="CSV",
                        help="optional CSV path for the per-cell table (default: none)")
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")


# The warm-up frame's seed: four words, where every timed frame's is three (its cell's) plus a spawn
# key, so the warm-up frame is never one of the timed frames.
_WARM_UP_KEY = 1


def _cell_config(args: argparse.Namespace, n: int, eps: float):
    from stereovo.simulation import SimulationConfig

    return SimulationConfig(
        n_correspondences=n, outlier_ratio=eps, noise_sigma=args.noise, outlier_mix=BENCH_OUTLIER_MIXES[args.outliers],
        outliers="hostile" if args.outliers == "hostile" else "default",
    )


def _cell_seed(args: argparse.Namespace, n: int, eps: float) -> list[int]:
    return [args.seed, n, int(round(eps * 1000))]


def warm_up(runners: dict[str, Callable], args: argparse.Namespace, n: int, eps: float) -> None:
    """Call every runner once, untimed, on a frame of the cell ``(n, eps)`` that no cell times.

    The first call of an estimator pays one-time costs (numba compiling or loading its kernels, a
    library's first allocations): 60-90 ms a frame where later calls take 1 ms. Paid inside the
    first cell, they would inflate its times and make every table depend on the cell order. The
    runners are seeded per call, so the timed frames' estimates are those of a run without it.
    """
    from stereovo.simulation import simulate_frame

    frame = simulate_frame(_cell_config(args, n, eps),
                           np.random.default_rng(np.random.SeedSequence([*_cell_seed(args, n, eps), _WARM_UP_KEY])))
    for runner in runners.values():
        runner(frame, args.seed)


def run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from stereovo.simulation import simulate_frame

    if args.no_peers:
        given = ([f"--superansac-sampler {args.superansac_sampler}"] if args.superansac_sampler else []) + (
            ["--superansac-rigid"] if args.superansac_rigid else [])
        if given:
            raise UsageError(f"{given[0]} applies to the SupeRANSAC peer, which --no-peers skips")
    if args.out is not None:
        check_output_file(args.out, "--out")  # before any computing, so no result is lost
    # Imported after the check: the benchmark package binds the simulator's functions when it loads.
    from stereovo.benchmark.peers import frame_errors

    ns, epsilons = list(args.ns), list(args.epsilons)
    runners = _runners(args)
    last_seed = args.seed + args.frames - 1  # frame i of a cell seeds every estimator with --seed + i
    if len(runners) > 1 and last_seed > PEER_SEED_MAX:
        raise UsageError(f"--seed {args.seed} with --frames {args.frames} seeds the peers up to {last_seed}; they take "
                         f"seeds up to {PEER_SEED_MAX} (OpenCV's generator takes a C int): a smaller --seed, or "
                         "--no-peers")
    print(f"threads: OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS', 'unset')}; times are wall-clock per frame")

    rows = []
    cells = [(n, eps) for n in ns for eps in epsilons]
    print("warming up: every estimator once on a frame of its own before timing", flush=True)
    warm_up(runners, args, *cells[0])
    with tqdm(total=len(cells) * args.frames * len(runners), desc="bench", unit="est",
              disable=args.no_progress) as bar:
        for n, eps in cells:
            config = _cell_config(args, n, eps)
            seq = np.random.SeedSequence(_cell_seed(args, n, eps))
            frames = [simulate_frame(config, np.random.default_rng(s)) for s in seq.spawn(args.frames)]
            for name, runner in runners.items():
                times, hyps, rot, ok = [], [], [], []
                for i, frame in enumerate(frames):
                    out = runner(frame, args.seed + i)
                    rot_deg, _, success = frame_errors(out, frame)
                    ok.append(success)
                    times.append(out.seconds)
                    hyps.append(out.hypotheses)
                    rot.append(rot_deg)
                    bar.update()
                hyps_known = [h for h in hyps if h >= 0]
                rows.append(
                    dict(
                        n=n, epsilon=eps, estimator=name,
                        median_ms=1000 * float(np.median(times)),
                        hypotheses_per_s=(sum(hyps_known) / sum(times)) if hyps_known else float("nan"),
                        success=float(np.mean(ok)),
                        median_rot_deg=float(np.median(rot)),
                    )
                )
    _print_table(rows, list(runners))
    if args.out is not None:
        import csv

        with open(args.out, "w", newline="") as fh:
            writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
            writer.writeheader()
            writer.writerows(rows)
        print(f"wrote {args.out}")
    return 0


def _print_table(rows: list[dict], names: list[str]) -> None:
    ours = names[0]
    header = f"{'N':>5} {'eps':>4} {'estimator':<22} {'ms/frame':>9} {'hyp/s':>9} {'success':>8} {'rot deg':>8} {'ours/this':>9}"
    print(header)
    print("-" * len(header))
    by_cell: dict[tuple, dict[str, dict]] = {}
    for row in rows:
        by_cell.setdefault((row["n"], row["epsilon"]), {})[row["estimator"]] = row
    for (n, eps), cell in by_cell.items():
        for name in names:
            r = cell[name]
            ratio = cell[ours]["median_ms"] / r["median_ms"] if r["median_ms"] > 0 else float("nan")
            print(
                f"{n:>5} {eps:>4.2f} {name:<22} {r['median_ms']:>9.2f} {r['hypotheses_per_s']:>9.0f} "
                f"{r['success']:>8.2f} {r['median_rot_deg']:>8.4f} {ratio:>9.2f}"
            )
