"""PROSAC with an uninformative (random) ordering against RANSAC on the same frames (issue 14 item 3).

With a random ordering PROSAC should behave like RANSAC (Chum & Matas 2005, "Matching with PROSAC -
progressive sample consensus", CVPR): this prints, per contamination, the mean hypotheses of both,
their ratio, the success rate (estimate ok and rotation error < 1 deg) and the miss rate (runs that
stop without ever having drawn an all-inlier sample, truth known), and PROSAC's n* at the stop.
``ransac+order`` is PROSAC's sampler with the adaptive stop over its schedule in place of PROSAC's
own rule (``ransac`` given ``order=``: the baseline report's ``ransac+prosac-order``).

    .venv/bin/python scripts/bench_prosac_ordering.py --frames 300 --eps 0.5 0.8
    .venv/bin/python scripts/bench_prosac_ordering.py --order perfect   # inliers first, shuffled
    .venv/bin/python scripts/bench_prosac_ordering.py --rule --told-at 1 30 100

``--rule``: PROSAC's stop alone, told the true consensus after ``--told-at`` draws on random
orderings (no geometry): its bound against RANSAC's (``k_n* / k_N``), the inlier share of the prefix
n* it picks, and how often the draws up to its stop hold no all-inlier sample.
"""

from __future__ import annotations

import argparse

import numpy as np

from stereovo.estimation.loop import run_ransac
from stereovo.estimation.estimator_options import EstimatorOptions
from stereovo.estimation.registry import method_spec
from stereovo.estimation.problem import StereoProblem
from stereovo.estimation.methods.prosac import ProsacTermination, prefix_draws
from stereovo.estimation.roles.samplers import ProsacSampler
from stereovo.geometry import rotation_error
from stereovo.simulation import SimulationConfig, simulate_frame


def record_all_inlier_draws(sampler, truth: np.ndarray) -> list[bool]:
    """Wrap ``sampler.draw`` on the instance: the returned list gets True once an all-inlier sample is drawn."""
    hit = [False]
    draw = sampler.draw

    def recording(batch, rng):
        samples = draw(batch, rng)
        hit[0] = hit[0] or bool(np.any(np.all(truth[samples], axis=1)))
        return samples

    sampler.draw = recording
    return hit


def ordering(kind: str, inlier: np.ndarray, g: np.random.Generator) -> np.ndarray:
    if kind == "random":
        return g.permutation(inlier.shape[0])
    return np.r_[g.permutation(np.flatnonzero(inlier)), g.permutation(np.flatnonzero(~inlier))]


def run_one(method: str, frame, options: EstimatorOptions, order, seed: int, extra: dict) -> dict:
    problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
    components = method_spec(method).build(problem, options, None, order, dict(extra))
    hit = record_all_inlier_draws(components.sampler, frame.truth.inlier)
    report = run_ransac(problem, components, np.random.default_rng(seed))
    right = bool(report.status == "ok" and np.degrees(rotation_error(report.rotation, frame.truth.rotation)) < 1.0)
    row = {"hypotheses": report.n_hypotheses, "right": right, "miss": not hit[0]}
    stop = components.termination
    if hasattr(stop, "n_star"):
        row["n_star"] = stop.n_star if stop.n_star is not None else problem.n
    return row


def rule_on_true_consensus(eps: float, n: int, orderings: int, confidence: float, told_at: int) -> None:
    n_inliers = int(round(n * (1 - eps)))
    k_n = float(prefix_draws(n_inliers, n, 1 - confidence))
    ratios, shares, misses, draws = [], [], 0, []
    for seed in range(orderings):
        g = np.random.default_rng(seed)
        truth = np.zeros(n, dtype=bool)
        truth[g.choice(n, n_inliers, replace=False)] = True
        sampler = ProsacSampler(g.permutation(n))
        stop = ProsacTermination(sampler, confidence=confidence, max_iterations=10**7)
        rng = np.random.default_rng(seed + 1)
        hit = bool(np.any(np.all(truth[sampler.draw(told_at, rng)], axis=1)))
        stop.on_new_best(truth, None)
        total = max(stop.required(n_inliers, n), told_at)
        if total > sampler.t:
            hit = hit or bool(np.any(np.all(truth[sampler.draw(total - sampler.t, rng)], axis=1)))
        misses += not hit
        ratios.append(stop.k_stop / k_n)
        shares.append(truth[sampler.order[: stop.n_star]].mean())
        draws.append(total)
    print(f"eps {eps}  N {n}  {orderings} random orderings  confidence {confidence}  consensus told after {told_at} draw(s)")
    print(f"  k_n*/k_N {np.mean(ratios):.3f}  inlier share at n* {np.mean(shares):.3f} (overall {n_inliers / n:.2f})  "
          f"mean draws {np.mean(draws):.1f} (RANSAC's bound {np.ceil(k_n):.0f})  "
          f"miss {misses / orderings:.3f} (allowed {1 - confidence:.2f})")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=300)
    parser.add_argument("--n", type=int, default=500)
    parser.add_argument("--eps", type=float, nargs="+", default=[0.5, 0.8])
    parser.add_argument("--order", choices=("random", "perfect"), default="random")
    parser.add_argument("--confidence", type=float, default=0.99)
    parser.add_argument("--enhanced", action="store_true", help="sample polish and local refit for both methods")
    parser.add_argument("--mix", type=float, nargs=3, default=None, metavar=("RANDOM", "STEREO", "MOVING"),
                        help="outlier_mix of the frames (default: the simulator's, with a moving object)")
    parser.add_argument("--seed0", type=int, default=10_000)
    parser.add_argument("--batch", type=int, default=None, help="batch_size = first_batch_size (1: one draw at a time)")
    parser.add_argument("--rule", action="store_true", help="the stop alone on the true consensus (see above)")
    parser.add_argument("--told-at", type=int, nargs="+", default=[1])
    args = parser.parse_args()
    if args.rule:
        for eps in args.eps:
            for told_at in args.told_at:
                rule_on_true_consensus(eps, args.n, args.frames, args.confidence, told_at)
        return
    enhanced = {"polish_iterations": 2, "local_refit": True} if args.enhanced else {}
    if args.batch is not None:
        enhanced.update(batch_size=args.batch, first_batch_size=args.batch)
    for eps in args.eps:
        mix = {} if args.mix is None else {"outlier_mix": tuple(args.mix)}
        config = SimulationConfig(n_correspondences=args.n, outlier_ratio=eps, **mix)
        rows = {"ransac": [], "prosac": [], "ransac+order": []}
        for i in range(args.frames):
            seed = args.seed0 + i
            frame = simulate_frame(config, seed)
            options = EstimatorOptions(noise_sigma=frame.noise_sigma, confidence=args.confidence, **enhanced)
            order = ordering(args.order, frame.truth.inlier, np.random.default_rng(seed))
            rows["ransac"].append(run_one("ransac", frame, options, None, seed, {}))
            rows["prosac"].append(run_one("prosac", frame, options, order, seed, {}))
            rows["ransac+order"].append(run_one("ransac", frame, options, order, seed, {}))
        mean = {m: float(np.mean([r["hypotheses"] for r in rows[m]])) for m in rows}
        print(f"eps {eps}  N {args.n}  {args.frames} frames  {args.order} order  confidence {args.confidence}"
              f"{'  enhanced' if args.enhanced else ''}{'' if args.mix is None else f'  outlier_mix {tuple(args.mix)}'}")
        for m in rows:
            h = np.array([r["hypotheses"] for r in rows[m]])
            print(f"  {m:12s} mean hyp {h.mean():8.1f}  median {np.median(h):7.1f}  "
                  f"success {np.mean([r['right'] for r in rows[m]]):.3f}  "
                  f"miss {np.mean([r['miss'] for r in rows[m]]):.3f}")
        n_star = np.array([r["n_star"] for r in rows["prosac"]])
        print(f"  ratio prosac/ransac {mean['prosac'] / mean['ransac']:.3f}   "
              f"ransac+order/ransac {mean['ransac+order'] / mean['ransac']:.3f}   "
              f"n* median {np.median(n_star):.0f}, below N in {np.mean(n_star < args.n):.2f} of runs")


if __name__ == "__main__":
    main()
