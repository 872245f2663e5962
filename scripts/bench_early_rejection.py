"""Does early rejection pay in wall time? waldsac (SPRT) and r-ransac (T(d,d)) against the same
composition with full verification.

For each N in {1000, 5000} and contamination eps in {0.5, 0.8}, on the same seeded frames, every
method is run twice: as registered, and with its verifier replaced by full scoring of every
hypothesis on every point and its stop by the plain adaptive bound (what the early-rejection
stop reduces to without a test). ``r-ransac:on`` is r-ransac with the pre-test kept on throughout
(the paper's fixed T(1,1); registered r-ransac switches it off once the measured rates say it
cannot pay). Each frame's two runs alternate ``--repeats`` times and each keeps its fastest (a
shared, loaded machine only ever adds time); ``--clock cpu`` (the default) times the process'
CPU time, which on a single-threaded run is its wall time minus the time other jobs held the
cores, ``--clock wall`` the wall time. Printed per cell: median time of each and their ratio,
median time per hypothesis and its ratio, median hypotheses drawn, success (rotation < 1 deg),
the time inside the verifier per verified hypothesis and its ratio, and for r-ransac the measured pass probability alpha of a good hypothesis, which decides whether
the T(1,1) pre-test can pay: with fit cost t_M (in point checks), the pre-test pays only if
``(t_M + 1 + P_pass N) / alpha < t_M + N`` (Matas & Chum 2004's cost model).

Compilation is warmed up first. Usage::

    python scripts/bench_early_rejection.py [--frames 25] [--repeats 7] [--clock cpu|wall] [--enhanced] [--json out.json]

(about five minutes on the project's 2-core machine; docs/performance.md records a run.)
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np

from stereovo.estimation.loop import run_ransac
from stereovo.estimation.estimator_options import EstimatorOptions
from stereovo.estimation.registry import method_spec
from stereovo.estimation.problem import StereoProblem
from stereovo.estimation.roles.solvers import minimal_hypotheses
from stereovo.estimation.roles.termination import AdaptiveTermination
from stereovo.estimation.roles.verification import FullVerification, ScoringContext
from stereovo.geometry import rotation_error
from stereovo.simulation import SimulationConfig, simulate_frame

ENHANCED = {"polish_iterations": 2, "local_refit": True, "refine": True}
CLOCKS = {"cpu": time.process_time, "wall": time.perf_counter}
clock = time.process_time


def base_method(method: str) -> str:
    return method.split(":", 1)[0]


def components(method: str, problem: StereoProblem, options: EstimatorOptions, full: bool, method_options=None):
    """``method``'s recipe; with ``full``, full verification and the plain adaptive bound instead."""
    c = method_spec(base_method(method)).build(problem, options, None, None, dict(method_options or {}))
    if method == "r-ransac:on":
        c.verifier.adaptive = False  # the pre-test stays on whatever the measured rates say
    if full:
        old = (c.verifier, c.termination)
        c.verifier = FullVerification()
        c.termination = AdaptiveTermination(options.confidence, int(options.max_iterations), sampler=c.sampler)
        c.listeners = [x for x in c.listeners if all(x is not o for o in old)] + [c.termination]
    return c


def fit_cost_in_point_checks(problem: StereoProblem, options: EstimatorOptions, c) -> float:
    """t_M: time of one minimal fit over the time of one point check of full scoring (measured)."""
    rng = np.random.default_rng(0)
    samples = np.stack([rng.choice(problem.n, 3, replace=False) for _ in range(256)])
    ctx = ScoringContext(problem, c.residual_model, c.quality, c.threshold_sq)
    R, t, _ = minimal_hypotheses(problem, samples, int(options.polish_iterations))
    best_fit = best_score = np.inf
    for _ in range(5):
        t0 = clock()
        minimal_hypotheses(problem, samples, int(options.polish_iterations))
        best_fit = min(best_fit, clock() - t0)
        t0 = clock()
        ctx.score(R, t)
        best_score = min(best_score, clock() - t0)
    return (best_fit / 256) / (best_score / (256 * problem.n))


def timed_run(method, problem, options, full, method_options, seed):
    """One run of ``method`` (or its full-verification twin): ``(report, components, seconds, seconds in
    the verifier)``."""
    c = components(method, problem, options, full, method_options)
    verify, spent = c.verifier.verify, [0.0]

    def timed(*a, **k):
        t0 = clock()
        out = verify(*a, **k)
        spent[0] += clock() - t0
        return out

    c.verifier.verify = timed
    t0 = clock()
    report = run_ransac(problem, c, np.random.default_rng(seed))
    return report, c, clock() - t0, spent[0]


def run_cell(method: str, n: int, eps: float, frames: int, extra: dict, method_options=None, repeats: int = 1) -> dict:
    times = {False: [], True: []}
    per_hyp = {False: [], True: []}
    verify_per_hyp = {False: [], True: []}
    draws = {False: [], True: []}
    right = {False: 0, True: 0}
    alphas, pass_rates, t_m, on_share = [], [], [], []
    for seed in range(frames):
        frame = simulate_frame(SimulationConfig(n_correspondences=n, outlier_ratio=eps), 9000 + seed)
        problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
        options = EstimatorOptions(noise_sigma=frame.noise_sigma, **extra)
        best = {}
        for _ in range(repeats):  # the same seeded run each time: only its time varies
            for full in (False, True):
                run = timed_run(method, problem, options, full, method_options, seed)
                if full not in best or run[2] < best[full][2]:
                    best[full] = run
        for full in (False, True):
            report, c, elapsed, in_verifier = best[full]
            times[full].append(elapsed)
            per_hyp[full].append(elapsed / max(report.n_hypotheses, 1))
            verify_per_hyp[full].append(in_verifier / max(report.n_scored, 1))
            draws[full].append(report.n_hypotheses)
            right[full] += report.status == "ok" and np.degrees(rotation_error(report.rotation, frame.truth.rotation)) < 1
            if not full and base_method(method) == "r-ransac":
                counters = report.counters or getattr(c.verifier, "counters", lambda: {})()
                if counters.get("tdd_alpha", -1) >= 0:
                    alphas.append(counters["tdd_alpha"])
                pass_rates.append(counters["tdd_passed"] / max(counters["tdd_tested"], 1))
                on_share.append(counters["tdd_on"] / max(counters["tdd_on"] + counters["tdd_off"], 1))
                if seed == 0:
                    t_m.append(fit_cost_in_point_checks(problem, options, c))
    row = {
        "method": method, "N": n, "eps": eps, "frames": frames,
        "time_ms": float(np.median(times[False]) * 1e3), "full_time_ms": float(np.median(times[True]) * 1e3),
        "per_hypothesis_us": float(np.median(per_hyp[False]) * 1e6),
        "full_per_hypothesis_us": float(np.median(per_hyp[True]) * 1e6),
        "verify_us": float(np.median(verify_per_hyp[False]) * 1e6),
        "full_verify_us": float(np.median(verify_per_hyp[True]) * 1e6),
        "hypotheses": float(np.median(draws[False])), "full_hypotheses": float(np.median(draws[True])),
        "success": right[False] / frames, "full_success": right[True] / frames,
    }
    row["time_ratio"] = row["time_ms"] / row["full_time_ms"]
    row["per_hypothesis_ratio"] = row["per_hypothesis_us"] / row["full_per_hypothesis_us"]
    row["verify_ratio"] = row["verify_us"] / row["full_verify_us"]
    if base_method(method) == "r-ransac":
        alpha = float(np.median(alphas)) if alphas else float("nan")
        p_pass = float(np.median(pass_rates))
        tm = float(t_m[0]) if t_m else float("nan")
        row.update(alpha=alpha, pass_rate=p_pass, t_m=tm, pretest_on_share=float(np.median(on_share)),
                   pretest_pays=bool(alpha > 0 and (tm + 1 + p_pass * n) / alpha < tm + n))
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=25, help="seeded frames per cell (default 25)")
    parser.add_argument("--sizes", type=int, nargs="+", default=[1000, 5000])
    parser.add_argument("--eps", type=float, nargs="+", default=[0.5, 0.8])
    parser.add_argument("--methods", nargs="+", default=["waldsac", "r-ransac", "r-ransac:on"],
                        help="methods; r-ransac:on keeps the pre-test on throughout")
    parser.add_argument("--repeats", type=int, default=7, help="runs per frame and route, the fastest kept (default 7)")
    parser.add_argument("--clock", choices=sorted(CLOCKS), default="cpu", help="process CPU time (default) or wall time")
    parser.add_argument("--enhanced", action="store_true", help="sample polish, local refit, LM refinement on")
    parser.add_argument("--json", help="also write the rows to this file")
    parser.add_argument("--method-option", action="append", default=[], metavar="NAME=VALUE",
                        help="a method option for the recipe (e.g. sprt_t_m=1000), repeatable")
    args = parser.parse_args()
    global clock
    clock = CLOCKS[args.clock]
    extra = ENHANCED if args.enhanced else {}
    method_options = {k: float(v) for k, v in (item.split("=", 1) for item in args.method_option)}

    for method in args.methods:  # warm-up: compile every kernel both routes use
        run_cell(method, 300, 0.5, 1, extra, method_options)

    rows = []
    print(f"clock {args.clock}, {args.frames} frames, fastest of {args.repeats} runs each; load average "
          f"{' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    print(f"{'method':11s} {'N':>5s} {'eps':>4s} | {'time ms':>8s} {'full ms':>8s} {'ratio':>6s} | "
          f"{'us/hyp':>7s} {'full':>7s} {'ratio':>6s} | {'verify us/hyp':>13s} {'full':>6s} {'ratio':>5s} | {'hyps':>6s} {'full':>6s} | {'succ':>4s} {'full':>4s} | notes")
    for method in args.methods:
        for n in args.sizes:
            for eps in args.eps:
                row = run_cell(method, n, eps, args.frames, extra, method_options, args.repeats)
                rows.append(row)
                note = ""
                if base_method(method) == "r-ransac":
                    note = (f"alpha {row['alpha']:.3f}, P(pass) {row['pass_rate']:.4f}, t_M {row['t_m']:.0f}: "
                            f"T(1,1) {'pays' if row['pretest_pays'] else 'does not pay'}; "
                            f"pre-test on for {100 * row['pretest_on_share']:.0f} % of hypotheses")
                print(f"{method:11s} {n:5d} {eps:4.1f} | {row['time_ms']:8.1f} {row['full_time_ms']:8.1f} "
                      f"{row['time_ratio']:6.2f} | {row['per_hypothesis_us']:7.1f} {row['full_per_hypothesis_us']:7.1f} "
                      f"{row['per_hypothesis_ratio']:6.2f} | {row['verify_us']:13.2f} {row['full_verify_us']:6.2f} "
                      f"{row['verify_ratio']:5.2f} | {row['hypotheses']:6.0f} {row['full_hypotheses']:6.0f} | "
                      f"{row['success']:4.2f} {row['full_success']:4.2f} | {note}", flush=True)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(rows, fh, indent=1)


if __name__ == "__main__":
    main()
