"""What scoring a hypothesis on a point costs: the 3-D Mahalanobis scorer in vector lanes against the
branching form it replaced, measured in one run.

On seeded frames (random mismatches at eps 0.2, the hostile preset at eps 0.8 and 0.9), draws
minimal samples, keeps those the rigidity check passes (the hypotheses the loop scores), fits them
and times ``mahalanobis_sq`` (stereovo/estimation/kernels/mahalanobis.py, capped at the
chi-square(3) 0.95 gate as the loop calls it) against a compiled loop over the same points through
``point_mahalanobis_sq``, the branching form (the scorer before 2026-12-06, and the compiled SPRT's
form today). It checks that both give the same distances bit for bit and prints nanoseconds per
point and hypothesis (best of ``--repeats`` runs of ``--calls`` calls, wall clock; numba's
compilation is warmed up first) and the ratio lanes / branching.

Usage::

    python scripts/bench_scoring.py [--hypotheses 64] [--calls 100] [--repeats 5]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from numba import njit

from stereovo.estimation.kernels.mahalanobis import mahalanobis_sq, point_columns, point_mahalanobis_sq
from stereovo.estimation.problem import StereoProblem
from stereovo.estimation.roles.sample_check import RigidityCheck
from stereovo.estimation.roles.scoring import CHI2_3_95
from stereovo.estimation.roles.solvers import minimal_hypotheses
from stereovo.simulation import SimulationConfig, simulate_frame

CELLS = (("random", 1000, 0.2), ("hostile", 200, 0.8), ("hostile", 500, 0.8), ("hostile", 500, 0.9),
         ("hostile", 1000, 0.9))


@njit(cache=False, nogil=True, error_model="numpy")
def branching_sq(R, t, X, Y, cam, sigma_sq, cap):
    """``mahalanobis_sq`` as it was: row after row through the branching point distance."""
    fx, fy, bl = cam[0], cam[1], cam[4]
    inv_fx, inv_fy, inv_fb = 1.0 / fx, 1.0 / fy, 1.0 / (fx * bl)
    v_variance = 1.0 / cam[5]
    H, N = R.shape[0], X.shape[0]
    out = np.empty((H, N))
    c_lateral = 2.0 * inv_fx * inv_fx + v_variance * inv_fy * inv_fy
    c_depth = 3.0 * inv_fb * inv_fb
    inv_depth, norm_x, norm_y = point_columns(X, Y)[6:]
    for h in range(H):
        norm_t = np.sqrt(t[h, 0] ** 2 + t[h, 1] ** 2 + t[h, 2] ** 2)
        for n in range(N):
            out[h, n] = point_mahalanobis_sq(
                R[h, 0, 0], R[h, 0, 1], R[h, 0, 2], R[h, 1, 0], R[h, 1, 1], R[h, 1, 2], R[h, 2, 0], R[h, 2, 1],
                R[h, 2, 2], t[h, 0], t[h, 1], t[h, 2], norm_t,
                X[n, 0], X[n, 1], X[n, 2], Y[n, 0], Y[n, 1], Y[n, 2], inv_depth[n], norm_x[n], norm_y[n],
                inv_fx, inv_fy, inv_fb, v_variance, c_lateral, c_depth, sigma_sq, cap,
            )
    return out


def fastest(fn, args, calls: int, repeats: int) -> float:
    """Seconds a call, best of ``repeats`` runs of ``calls`` calls."""
    fn(*args)
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        for _ in range(calls):
            fn(*args)
        best = min(best, (time.perf_counter() - start) / calls)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--hypotheses", type=int, default=64, help="rigidity-checked hypotheses per call")
    parser.add_argument("--calls", type=int, default=100)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    print(f"{'frames':>8} {'N':>5} {'eps':>4} {'H':>4} {'branching ns':>13} {'lanes ns':>9} {'lanes / branching':>18}")
    for outliers, n, eps in CELLS:
        hostile = outliers == "hostile"  # else random mismatches only, as `vo-gym bench` draws them
        config = SimulationConfig(n_correspondences=n, outlier_ratio=eps, outliers="hostile" if hostile else "default",
                                  outlier_mix=None if hostile else (1.0, 0.0, 0.0))
        frame = simulate_frame(config, np.random.default_rng(n))
        problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma).usable_subproblem()[0]
        samples = np.stack([rng.choice(problem.n, 3, replace=False) for _ in range(40 * args.hypotheses)])
        samples = samples[RigidityCheck(0.999).accept(problem, samples)][: args.hypotheses]
        R, t, valid = minimal_hypotheses(problem, samples, 2)
        R, t = np.ascontiguousarray(R[valid]), np.ascontiguousarray(t[valid])
        call = (R, t, problem.points_prev, problem.points_curr, problem.camera.parameters,
                problem.noise_sigma**2, CHI2_3_95)
        if not np.array_equal(mahalanobis_sq(*call), branching_sq(*call)):
            raise SystemExit(f"{outliers} N {n} eps {eps}: the two scorers differ")
        per_point = R.shape[0] * problem.n
        old = fastest(branching_sq, call, args.calls, args.repeats) / per_point * 1e9
        new = fastest(mahalanobis_sq, call, args.calls, args.repeats) / per_point * 1e9
        print(f"{outliers:>8} {n:>5} {eps:>4} {R.shape[0]:>4} {old:>13.1f} {new:>9.1f} {new / old:>18.2f}")


if __name__ == "__main__":
    main()
