"""The environments' parts that were made faster, against the formulation each replaced, in one
process: per step of ``vo_gym/StereoVOAdaptive-v0``, a batch's draw (``WeightedSampler`` built
from the agent's weights, then four samples, against ``WeightedDraw``) and the selection read
twice a step (the frame's masks concatenated, against the buffer; the bool buffer, against its
float64 copy), the priors' normalisation with the draw's tables (numpy's and ``WeightedDraw``'s,
against :func:`vo_gym.in_frame.normalised_priors`), the padded batch infos (numpy's fills and copies,
against :func:`vo_gym.step_info.padded_batch`) and a frame's all-inlier info (numpy's expression,
against :func:`vo_gym.step_info.any_all_inlier`); per frame of every env, the
rigid-consistency counts of the features (every pair through the double-precision test, against
the single-precision screen), on the usable rows of simulated frames (default and hostile); with
``--before DIR`` (a checkout of earlier code) also a frame's whole ``compute_features``, DIR's
``vo_gym/features.py`` against this one's; and the stable descending order of a frame's scores
(``np.argsort(-x, kind="stable")`` against :func:`vo_gym.ordering.descending_order`), on one array
sorted again and again and on 64 fresh arrays in turn (numpy's merge sort is three times slower on
fresh values: a branch predictor learns one repeated array). Each is timed ``--repeats``
times over ``--loops`` calls, the fastest kept (process CPU time); the results are checked equal
first, on generators seeded alike. Usage::

    python scripts/bench_env_parts.py [--n 500] [--repeats 7] [--loops 200] [--before DIR]
"""

from __future__ import annotations

import argparse
import importlib.util
import itertools
import time
from pathlib import Path

import numpy as np

from stereovo.estimation import StereoProblem
from stereovo.estimation.methods.bansac import WeightedDraw
from stereovo.estimation.roles.samplers import WeightedSampler
from stereovo.simulation import SimulationConfig, simulate_frame
from vo_gym import features as F
from vo_gym.action_box import exp_shifted
from vo_gym.in_frame import normalised_priors
from vo_gym.step_info import any_all_inlier, padded_batch
from vo_gym.ordering import descending_order


def fastest(fn, loops: int, repeats: int) -> float:
    best = np.inf
    for _ in range(repeats):
        start = time.process_time()
        for _ in range(loops):
            fn()
        best = min(best, (time.process_time() - start) / loops)
    return best


def _numpy_priors(logits: np.ndarray) -> WeightedDraw:
    """The in-frame step's priors before they were compiled: numpy's softmax, then ``WeightedDraw``."""
    weights = np.exp(logits - logits.max())
    weights /= weights.sum()
    return WeightedDraw(weights)


def _numpy_padded(samples: np.ndarray, masks: np.ndarray, rows: int, columns: int) -> np.ndarray:
    """The adaptive env's padded batch infos before they were compiled (the inliers returned)."""
    batch_samples = np.full((rows, 3), -1, dtype=np.int64)
    batch_samples[: samples.shape[0]] = samples
    batch_inliers = np.zeros((rows, columns), dtype=bool)
    batch_inliers[: masks.shape[0], : masks.shape[1]] = masks
    return batch_inliers


def _compiled_padded(samples: np.ndarray, masks: np.ndarray, rows: int, columns: int) -> np.ndarray:
    batch_samples, batch_inliers = np.empty((rows, 3), dtype=np.int64), np.empty((rows, columns), dtype=bool)
    padded_batch(samples, masks, batch_samples, batch_inliers)
    return batch_inliers


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split(" Usage::")[0])
    parser.add_argument("--n", type=int, default=500)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--loops", type=int, default=200)
    parser.add_argument("--before", default=None, help="a checkout whose vo_gym/features.py is the 'before'")
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    n = args.n
    logits = rng.uniform(-3, 3, n)
    weights = np.exp(logits - logits.max())
    weights /= weights.sum()
    masks = [rng.random((4, n)) < 0.4 for _ in range(8)]  # eight batches of four scored hypotheses
    buffer = np.concatenate(masks)
    buffer_f64 = buffer.astype(np.float64)
    samples = rng.integers(0, n, (4, 3)).astype(np.int64)
    all_samples, labels = rng.integers(0, n, (12, 3)).astype(np.int64), rng.random(n) < 0.3
    assert np.array_equal(WeightedSampler(weights).draw(400, np.random.default_rng(1)),
                          WeightedDraw(weights).draw(400, np.random.default_rng(1)))
    g = np.random.default_rng(2)
    checks = [
        ("adaptive batch draw (4 samples)",
         lambda: WeightedSampler(weights).draw(4, g).shape,
         lambda: WeightedDraw(weights).draw(4, g).shape),
        ("adaptive selection (32 scored)",
         lambda: int(np.argmax(np.concatenate(masks) @ weights)),
         lambda: int(np.argmax(buffer[:32] @ weights))),
        ("adaptive selection, float64 masks (32)",
         lambda: int(np.argmax(buffer[:32] @ weights)),
         lambda: int(np.argmax(buffer_f64[:32] @ weights))),
        ("adaptive priors and draw tables",
         lambda: _numpy_priors(logits).cdf,
         lambda: normalised_priors(exp_shifted(logits)).cdf),
        ("adaptive padded batch infos (4 x N)",
         lambda: _numpy_padded(samples, masks[0], 4, n),
         lambda: _compiled_padded(samples, masks[0], 4, n)),
        ("adaptive all-inlier info (12 samples)",
         lambda: bool(all_samples.shape[0] and np.any(np.all(labels[all_samples], axis=1))),
         lambda: any_all_inlier(all_samples, labels)),
    ]
    fresh = [rng.random(n) for _ in range(64)]
    for label, arrays in (("one array again", fresh[:1]), ("64 fresh arrays", fresh)):
        numpy_turn, radix_turn = itertools.cycle(arrays), itertools.cycle(arrays)
        checks.append((f"score order ({label})",
                       lambda t=numpy_turn: np.argsort(-next(t), kind="stable"),
                       lambda t=radix_turn: descending_order(next(t))))
    for outliers in ("default", "hostile"):
        frame = simulate_frame(SimulationConfig(n_correspondences=n, outlier_ratio=0.5, outliers=outliers), rng=3)
        problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, 0.5)
        rows = np.flatnonzero(problem.usable_mask)
        s2 = (np.trace(problem.cov_prev[rows], axis1=1, axis2=2) + np.trace(problem.cov_curr[rows], axis1=1, axis2=2))
        anchors = np.sort(np.argsort(-frame.scores[rows], kind="stable")[: F.MAX_ANCHORS]).astype(np.int64)
        inputs = (np.ascontiguousarray(problem.points_prev[rows]), np.ascontiguousarray(problem.points_curr[rows]),
                s2, anchors, 9.0)
        checks.append((f"consistency counts ({outliers}, {rows.size} x {anchors.size})",
                       lambda a=inputs: F._consistent_pairs_exact(*a), lambda a=inputs: F._consistent_pairs(*a)))
    if args.before:
        spec = importlib.util.spec_from_file_location("features_before", Path(args.before) / "vo_gym" / "features.py")
        before_features = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(before_features)
        frame = simulate_frame(SimulationConfig(n_correspondences=n, outlier_ratio=0.5), rng=4)
        problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, 0.5)
        motion = (frame.truth.rotation, frame.truth.translation)
        inputs = (frame.prev, frame.curr, frame.scores, frame.camera, 0.5, motion)
        checks.append(("compute_features (a frame, reused problem)",
                       lambda a=inputs: before_features.compute_features(*a, problem=problem),
                       lambda a=inputs: F.compute_features(*a, problem=problem)))
    print(f"{'part':<40} {'before us':>10} {'after us':>9} {'after/before':>13}")
    for name, before, after in checks:
        assert np.array_equal(np.asarray(before()), np.asarray(after())), name
        b = fastest(before, args.loops, args.repeats)
        a = fastest(after, args.loops, args.repeats)
        print(f"{name:<40} {1e6 * b:>10.1f} {1e6 * a:>9.1f} {a / b:>13.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
