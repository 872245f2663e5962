"""``vo-gym bench``: time the estimator core against optional peers on identical frames.

For every (N, epsilon) cell the same simulated frames go to our core and, when
the ``peers`` extra is installed, to OpenCV's ``solvePnPRansac`` and PoseLib's
``estimate_absolute_pose`` (3-D points triangulated at k-1, left-image pixels
at k). It prints per-frame median time, hypotheses per second, success rate
and median rotation error, and the ratio of our median time to each peer's.
Speed is measured here, never asserted in tests.
"""

from __future__ import annotations

import argparse
import os
import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

from vo_gym_cli.commands.common import (
    bounded_int,
    check_output_file,
    csv_list,
    finite_float,
    method_name,
    positive_int,
    score_inputs,
)
from vo_gym_cli.commands.common import seed as seed_type

DEFAULT_NS = (200, 500, 1000)
DEFAULT_EPSILONS = (0.2, 0.5, 0.8)
PEER_REPROJECTION_PX = 2.0  # peers judge one image; 2 px at sigma 0.5 is their usual setting
PEER_MAX_ITERATIONS = 10_000
# Outlier kinds (random, stereo, moving-object weights). "random" is the default because a random
# mismatch corrupts the left pixel at k, which every estimator here uses, so the peers and we face
# the same contamination. A stereo mismatch at k corrupts only the right pixel at k: an outlier for
# our two-image core but invisible to a one-image PnP peer, which then faces a lower epsilon.
BENCH_OUTLIER_MIXES = {"random": (1.0, 0.0, 0.0), "random+stereo": (0.8, 0.2, 0.0)}


@dataclass
class Outcome:
    rotation: np.ndarray
    translation: np.ndarray
    hypotheses: int
    seconds: float


def _ours(method: str) -> Callable:
    from stereovo import estimate_motion

    inputs = score_inputs(method)  # PROSAC / guided MLESAC sample by the match scores

    def run(frame, seed: int) -> Outcome:
        given = {key.removesuffix("_fn"): fn(frame) for key, fn in inputs.items()}
        start = time.perf_counter()
        est = estimate_motion(frame.prev, frame.curr, frame.camera, method=method, rng=seed, noise_sigma=frame.noise_sigma,
                              **given)
        elapsed = time.perf_counter() - start
        return Outcome(est.rotation, est.translation, est.n_hypotheses, elapsed)

    return run


def _opencv() -> Callable | None:
    try:
        import cv2
    except ImportError:
        return None
    cv2.setNumThreads(1)

    def run(frame, seed: int) -> Outcome:
        cv2.setRNGSeed(seed)
        X = frame.camera.triangulate(frame.prev)
        start = time.perf_counter()
        ok, rvec, tvec, inliers = cv2.solvePnPRansac(
            X, frame.curr[:, :2].copy(), frame.camera.intrinsics, None,
            iterationsCount=PEER_MAX_ITERATIONS, reprojectionError=PEER_REPROJECTION_PX,
            confidence=0.99, flags=cv2.SOLVEPNP_AP3P,
        )
        elapsed = time.perf_counter() - start
        if not ok:
            return Outcome(np.eye(3), np.zeros(3), 0, elapsed)
        R, _ = cv2.Rodrigues(rvec)
        # OpenCV does not report its iteration count; -1 marks it unknown.
        return Outcome(R, tvec.ravel(), -1, elapsed)

    return run


def _poselib() -> Callable | None:
    try:
        import poselib
    except ImportError:
        return None

    def run(frame, seed: int) -> Outcome:
        cam = frame.camera
        camera = {"model": "PINHOLE", "width": cam.width, "height": cam.height, "params": [cam.fx, cam.fy, cam.cx, cam.cy]}
        X = cam.triangulate(frame.prev)
        start = time.perf_counter()
        pose, info = poselib.estimate_absolute_pose(
            frame.curr[:, :2].copy(), X, camera,
            {"max_reproj_error": PEER_REPROJECTION_PX, "max_iterations": PEER_MAX_ITERATIONS, "success_prob": 0.99, "seed": seed},
            {},
        )
        elapsed = time.perf_counter() - start
        return Outcome(pose.R, np.asarray(pose.t), int(info.get("iterations", -1)), elapsed)

    return run


def add_parser(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--ns", type=csv_list(bounded_int("--ns", 3), "--ns"), default=list(DEFAULT_NS),
                        metavar="N,...", help="comma-separated correspondence counts N (each >= 3)")
    parser.add_argument("--epsilons", type=csv_list(finite_float("--epsilons", 0.0, 1.0, high_open=True), "--epsilons"),
                        default=list(DEFAULT_EPSILONS), metavar="E,...",
                        help="comma-separated contaminations, each in [0, 1)")
    parser.add_argument(
        "--frames", type=positive_int("--frames"), default=100,
        help="frames per (N, epsilon) cell (a median rotation error over fewer frames can tie by chance)",
    )
    parser.add_argument("--method", type=method_name("--method"), default="probabilistic",
                        help="our method to time (PROSAC-style methods get the match scores' order, "
                             "guided MLESAC the scores calibrated to inlier probabilities)")
    parser.add_argument(
        "--outliers", choices=sorted(BENCH_OUTLIER_MIXES), default="random",
        help="outlier kinds: random mismatches (same contamination for every estimator) or a stereo blend",
    )
    parser.add_argument("--noise", type=finite_float("--noise", 1e-3, 1e3), default=0.5,
                        help="pixel noise sigma (px), in [0.001, 1000]")
    parser.add_argument("--seed", type=seed_type, default=0, help="seed of the frames and of the estimators (>= 0)")
    parser.add_argument("--no-peers", action="store_true", help="skip OpenCV and PoseLib even if installed")
    parser.add_argument("--out", default=None, metavar="CSV",
                        help="optional CSV path for the per-cell table (default: none)")


def run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from stereovo.geometry import rotation_error
    from stereovo.metrics import is_success
    from stereovo.simulation import SimulationConfig, simulate_frame

    if args.out:
        check_output_file(args.out, "--out")  # before any computing, so no result is lost
    ns, epsilons = list(args.ns), list(args.epsilons)
    runners: dict[str, Callable] = {f"ours:{args.method}": _ours(args.method)}
    if not args.no_peers:
        for name, factory in (("opencv", _opencv), ("poselib", _poselib)):
            runner = factory()
            if runner is None:
                print(f"note: {name} is not installed (pip install -e '.[peers]'); skipping it")
            else:
                runners[name] = runner
    print(f"threads: OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS', 'unset')}; times are wall-clock per frame")

    rows = []
    cells = [(n, eps) for n in ns for eps in epsilons]
    with tqdm(total=len(cells) * args.frames * len(runners), desc="bench", unit="est") as bar:
        for n, eps in cells:
            config = SimulationConfig(
                n_correspondences=n, outlier_ratio=eps, noise_sigma=args.noise, outlier_mix=BENCH_OUTLIER_MIXES[args.outliers]
            )
            seq = np.random.SeedSequence([args.seed, n, int(round(eps * 1000))])
            frames = [simulate_frame(config, np.random.default_rng(s)) for s in seq.spawn(args.frames)]
            for name, runner in runners.items():
                times, hyps, rot, ok = [], [], [], []
                for i, frame in enumerate(frames):
                    out = runner(frame, args.seed + i)
                    r_err = float(rotation_error(out.rotation, frame.truth.rotation))
                    t_err = float(np.linalg.norm(out.translation - frame.truth.translation))
                    ok.append(bool(is_success(r_err, t_err, np.linalg.norm(frame.truth.translation))))
                    times.append(out.seconds)
                    hyps.append(out.hypotheses)
                    rot.append(np.degrees(r_err))
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
    if args.out:
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
