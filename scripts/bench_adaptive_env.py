#!/usr/bin/env python
"""Steps per second of the in-frame adaptive environment, against the one-shot environment in the same run.

Usage::

    .venv/bin/python scripts/bench_adaptive_env.py            # N = 500, batch 4, 16 hypotheses a frame
    .venv/bin/python scripts/bench_adaptive_env.py --steps 2000 --batch-size 2

One adaptive step is one batch of hypotheses within a frame (the action: uniform logits, stop once
``--per-frame`` hypotheses are drawn); one step of ``vo_gym/StereoVO-v0`` is a whole frame with a budget
of ``--per-frame``. Both are timed in this one single-threaded process after a warm-up (numba
compilation), medians over ``--repeats``; printed: adaptive steps/s and frames/s, one-shot frames/s,
and the ratio of frame rates (the price of stepping a frame batch by batch).
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import time  # noqa: E402

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402

import vo_gym  # noqa: E402,F401  (registers the ids)


def adaptive_rate(args) -> tuple[float, float]:
    env = gym.make("vo_gym/StereoVOAdaptive-v0", n_correspondences=args.n, batch_size=args.batch_size,
                   n_frames=args.n_frames, outlier_ratio=args.epsilon)
    env.reset(seed=0)
    action = np.zeros(env.action_space.shape, np.float32)

    def run(steps: int) -> tuple[int, int, float]:
        frames, start = 0, time.perf_counter()
        for _ in range(steps):
            action[-1] = 1.0 if env.unwrapped.frame_hypotheses >= args.per_frame else -1.0
            _, _, _, truncated, info = env.step(action)
            frames += info["frame_done"]
            if truncated:
                env.reset()
        return steps, frames, time.perf_counter() - start

    run(args.warmup)
    runs = sorted((run(args.steps) for _ in range(args.repeats)), key=lambda r: r[0] / r[2])
    steps, frames, seconds = runs[len(runs) // 2]
    return steps / seconds, frames / seconds


def one_shot_rate(args) -> float:
    env = gym.make("vo_gym/StereoVO-v0", n_correspondences=args.n, budget=args.per_frame, n_frames=args.n_frames,
                   outlier_ratio=args.epsilon)
    env.reset(seed=0)
    action = np.zeros(env.action_space.shape, np.float32)

    def run(steps: int) -> float:
        start = time.perf_counter()
        for _ in range(steps):
            if env.step(action)[3]:
                env.reset()
        return steps / (time.perf_counter() - start)

    run(args.warmup)
    rates = sorted(run(args.steps // 4 + 1) for _ in range(args.repeats))
    return rates[len(rates) // 2]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=500)
    parser.add_argument("--batch-size", type=int, default=4)
    parser.add_argument("--per-frame", type=int, default=16)
    parser.add_argument("--epsilon", type=float, default=0.5)
    parser.add_argument("--n-frames", type=int, default=50)
    parser.add_argument("--steps", type=int, default=500)
    parser.add_argument("--warmup", type=int, default=50)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    steps_s, frames_s = adaptive_rate(args)
    one_shot = one_shot_rate(args)
    print(f"adaptive env: {steps_s:.0f} steps/s ({frames_s:.1f} frames/s, batch {args.batch_size}, "
          f"{args.per_frame} hypotheses a frame, N {args.n})")
    print(f"one-shot env: {one_shot:.1f} frames/s (budget {args.per_frame})")
    print(f"frame-rate ratio adaptive / one-shot: {frames_s / one_shot:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
