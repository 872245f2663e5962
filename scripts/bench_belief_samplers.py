"""What a hypothesis costs BANSAC and ARS, compiled against their numpy formulation and against
``ransac`` and ``probabilistic``, measured in one run.

On the same seeded frames (N 500, eps 0.5 by default; half the frames with informative priors),
each method runs with the compiled samplers and, for bansac / p-bansac / ars, with the numpy
samplers they replaced (tests/support/belief_samplers.py, patched in; they take the shared loop's
steps), the runs of a frame alternating ``--repeats`` times, each keeping its fastest (a shared
machine only adds time), timed in process CPU time. Rows ``:loop`` run the compiled samplers in the
loop's steps instead of the methods' compiled searches (stereovo/estimation/kernels/bansac_runner.py).
It checks that each run gives the numpy reference's estimate and prints, per method, the median
time per frame, the time per hypothesis (total over total), and the ratios: compiled over numpy,
and per hypothesis over ``ransac``, over ``ransac`` in batches of one hypothesis (the paper's
BANSAC updates after every hypothesis, so the loop runs one-hypothesis batches), over
``probabilistic`` (the same Mahalanobis judge), and of the compiled search over the loop's steps.
Times are ratios within this run; numba's compilation is warmed up first.

Usage::

    python scripts/bench_belief_samplers.py [--n 500] [--eps 0.5] [--frames 8] [--repeats 3]
"""

from __future__ import annotations

import argparse
import contextlib
import sys
import time
from pathlib import Path

import numpy as np

from stereovo.estimation.methods import ars, bansac
from stereovo.estimation import estimate_motion
from stereovo.simulation import SimulationConfig, simulate_frame

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository root, for the tests' package
from tests.support.belief_samplers import ReferenceArsSampler, ReferenceBansacSampler  # noqa: E402

METHODS = (
    ("ransac", {}, False),
    ("ransac:batch-1", {"batch_size": 1, "first_batch_size": 1}, False),
    ("probabilistic", {}, False),
    ("bansac", {}, True),
    ("bansac:loop", {}, True),
    ("p-bansac", {}, True),
    ("p-bansac:loop", {}, True),
    ("bansac:batch-16", {"bansac_batch": 16}, True),
    ("ars", {}, True),
)
"""``(row, options, has a numpy reference)``; a row ``method:loop`` runs the method's steps in the
shared loop instead of its compiled search (``bansac.COMPILED_SEARCH`` off)."""


@contextlib.contextmanager
def numpy_samplers():
    """The numpy samplers in place of the compiled ones, for the methods' builders."""
    saved = bansac.BansacSampler, ars.ArsSampler
    bansac.BansacSampler, ars.ArsSampler = ReferenceBansacSampler, ReferenceArsSampler
    try:
        yield
    finally:
        bansac.BansacSampler, ars.ArsSampler = saved


@contextlib.contextmanager
def search_path(row: str):
    """The shared loop's steps in place of BANSAC's compiled search for a ``:loop`` row."""
    saved = bansac.COMPILED_SEARCH
    bansac.COMPILED_SEARCH = saved and not row.endswith(":loop")
    try:
        yield
    finally:
        bansac.COMPILED_SEARCH = saved


def timed(frame, method: str, options: dict, priors, seed: int):
    with search_path(method):
        start = time.process_time()
        est = estimate_motion(frame.prev, frame.curr, frame.camera, method=method.split(":")[0], priors=priors,
                              rng=seed, noise_sigma=frame.noise_sigma, **options)
        return time.process_time() - start, est


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, default=500)
    parser.add_argument("--eps", type=float, default=0.5)
    parser.add_argument("--frames", type=int, default=8)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    config = SimulationConfig(n_correspondences=args.n, outlier_ratio=args.eps, noise_sigma=0.5)
    frames = [simulate_frame(config, np.random.default_rng(s)) for s in range(args.frames)]
    priors = [np.where(f.truth.inlier, 0.8, 0.3) if i % 2 == 0 else None for i, f in enumerate(frames)]
    for method, options, _ in METHODS:  # compile / load every kernel before timing
        timed(frames[0], method, options, priors[0], 0)
    rows = {}
    for method, options, has_reference in METHODS:
        compiled_t, numpy_t, hyps = [], [], []
        for i, frame in enumerate(frames):
            best_c = best_n = np.inf
            for _ in range(args.repeats):
                dt, est = timed(frame, method, options, priors[i], i)
                best_c = min(best_c, dt)
                if has_reference:
                    with numpy_samplers():
                        dt_ref, ref = timed(frame, method, options, priors[i], i)
                    best_n = min(best_n, dt_ref)
                    if not (np.array_equal(est.rotation, ref.rotation) and np.array_equal(est.inliers, ref.inliers)
                            and est.n_hypotheses == ref.n_hypotheses and est.counters == ref.counters):
                        raise SystemExit(f"{method}: compiled and numpy samplers disagree on frame {i}")
            compiled_t.append(best_c)
            numpy_t.append(best_n)
            hyps.append(est.n_hypotheses)
        rows[method] = dict(ms=1e3 * np.median(compiled_t), us_hyp=1e6 * sum(compiled_t) / sum(hyps),
                            numpy_us_hyp=1e6 * sum(numpy_t) / sum(hyps) if has_reference else np.nan,
                            hyps=float(np.mean(hyps)))
    ransac, batch1, prob = rows["ransac"]["us_hyp"], rows["ransac:batch-1"]["us_hyp"], rows["probabilistic"]["us_hyp"]
    print(f"N {args.n}, eps {args.eps}, {args.frames} frames (half with priors), best of {args.repeats}, process CPU time")
    header = (f"{'method':<17} {'ms/frame':>9} {'hyp':>6} {'us/hyp':>8} {'numpy us/hyp':>13} {'compiled/numpy':>15} "
              f"{'/ransac':>8} {'/ransac b1':>10} {'/probab.':>9} {'search/loop':>12}")
    print(header)
    print("-" * len(header))
    for method, r in rows.items():
        loop = rows.get(f"{method}:loop", {}).get("us_hyp", np.nan)  # the compiled search over the loop's steps
        print(f"{method:<17} {r['ms']:>9.2f} {r['hyps']:>6.0f} {r['us_hyp']:>8.1f} {r['numpy_us_hyp']:>13.1f} "
              f"{r['us_hyp'] / r['numpy_us_hyp']:>15.2f} {r['us_hyp'] / ransac:>8.2f} {r['us_hyp'] / batch1:>10.2f} "
              f"{r['us_hyp'] / prob:>9.2f} {r['us_hyp'] / loop:>12.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
