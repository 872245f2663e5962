"""Consistency of the estimate's pose covariance: mean NEES over seeded frames, and a histogram.

The normalised estimation error squared ``e^T C^-1 e`` of a consistent 6-D covariance follows
chi-square(6) (mean 6). ``e = (log(R_est R_true^T), t_est - t_true)`` (rad, m), ``C`` the
estimate's ``covariance``. Prints the mean, the median and the fraction above the chi-square(6)
0.95 quantile; with ``--png`` writes the histogram against the chi-square(6) density.

    python scripts/pose_nees.py --frames 500 --outliers 0.5 --png docs/img/pose_nees.png
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from scipy.stats import chi2

from stereovo.estimation import estimate_motion
from stereovo.geometry import so3_log
from stereovo.simulation import SimulationConfig, simulate_frame


def error_vector(R_est: np.ndarray, t_est: np.ndarray, R_true: np.ndarray, t_true: np.ndarray) -> np.ndarray:
    """``(log(R_est R_true^T), t_est - t_true)``: rotation (rad) first, then translation (m)."""
    return np.concatenate([so3_log(R_est @ R_true.T), t_est - t_true])


def nees_values(frames: int, outliers: float, n: int, method: str, seed: int) -> tuple[np.ndarray, int]:
    """NEES of each ok estimate over ``frames`` seeded frames, and the number of failed estimates."""
    values, failed = [], 0
    for k in range(frames):
        frame = simulate_frame(SimulationConfig(n_correspondences=n, outlier_ratio=outliers), rng=seed + k)
        est = estimate_motion(frame.prev, frame.curr, frame.camera, method=method, rng=seed + k)
        if not est.ok:
            failed += 1
            continue
        e = error_vector(est.rotation, est.translation, frame.truth.rotation, frame.truth.translation)
        values.append(float(e @ np.linalg.solve(est.covariance, e)))
    return np.array(values), failed


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=500)
    parser.add_argument("--outliers", type=float, default=0.5)
    parser.add_argument("--n", type=int, default=500, help="correspondences per frame")
    parser.add_argument("--method", default="probabilistic")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--png", type=Path, default=None, help="write the NEES histogram here")
    args = parser.parse_args(argv)
    values, failed = nees_values(args.frames, args.outliers, args.n, args.method, args.seed)
    print(f"{args.method}, eps {args.outliers}, N {args.n}, {args.frames} frames ({failed} failed)")
    print(f"  mean NEES {values.mean():.3f} (chi-square(6): 6)   median {np.median(values):.3f} "
          f"({chi2.median(6):.3f})   above the 0.95 quantile {np.mean(values > chi2.ppf(0.95, 6)):.3f} (0.05)")
    if args.png is not None:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(6, 3.6))
        top = max(30.0, float(np.quantile(values, 0.995)))
        ax.hist(np.minimum(values, top), bins=60, range=(0, top), density=True, alpha=0.6, label="NEES of the estimates")
        grid = np.linspace(0, top, 400)
        ax.plot(grid, chi2.pdf(grid, 6), "k-", label="chi-square(6)")
        ax.set_xlabel("NEES  e^T C^-1 e")
        ax.set_ylabel("density")
        ax.set_title(f"{args.method}, eps {args.outliers}, N {args.n}: mean {values.mean():.2f} over {values.size}")
        ax.legend()
        fig.tight_layout()
        args.png.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(args.png, dpi=120)
        print(f"  wrote {args.png}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
