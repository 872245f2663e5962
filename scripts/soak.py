"""Soak benchmark: many environment steps and many estimates, printing resident memory as they run.

    .venv/bin/python scripts/soak.py                   # 10,000 env steps and 10,000 estimates
    .venv/bin/python scripts/soak.py --steps 2000      # a shorter run

Prints the resident set size (RSS, MB) after every ``--every`` steps and its growth since the
first report (taken after a warm-up, so numba compilation and first allocations are not counted).
A leak shows as growth that keeps rising; the allocator's noise is a few MB up and down.

What is allowed to grow: the environment keeps the estimated poses of the *current* episode (for
``render`` and the episode-end trajectory metrics), one 4x4 float64 pose (128 B) per step plus a
success and a fallback flag, so at most ``n_frames + 1`` poses; ``reset`` starts a new list. The
script prints that bound and checks the history never exceeds it.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np


def rss_mb() -> float:
    """Resident set size of this process in MB (Linux /proc; else the peak from getrusage)."""
    try:
        with open("/proc/self/statm") as fh:
            pages = int(fh.read().split()[1])
        return pages * os.sysconf("SC_PAGE_SIZE") / 2**20
    except (OSError, ValueError, IndexError):
        import resource

        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def soak_env(steps: int, every: int, n_frames: int, n: int, seed: int) -> list[float]:
    import gymnasium as gym

    import vo_gym  # noqa: F401

    env = gym.make("vo_gym/StereoVO-v0", n_frames=n_frames, n_correspondences=n)
    unwrapped = env.unwrapped
    rng = np.random.default_rng(seed)
    env.reset(seed=seed)
    for _ in range(min(50, steps)):  # warm-up: compilation and first allocations
        _, _, _, truncated, _ = env.step(env.action_space.sample())
        if truncated:
            env.reset()
    bound = n_frames + 1
    print(f"environment: {steps} steps, episodes of {n_frames} frames, N {n}; pose history bound "
          f"{bound} poses = {bound * 128 / 1024:.1f} KiB per episode (4x4 float64 each)")
    base, growth, longest = rss_mb(), [], 0
    start = time.perf_counter()
    for step in range(1, steps + 1):
        action = rng.normal(size=env.action_space.shape).astype(np.float32)
        _, _, _, truncated, _ = env.step(action)
        longest = max(longest, len(unwrapped.estimated_poses))
        if truncated:
            env.reset()
        if step % every == 0:
            now = rss_mb()
            growth.append(now - base)
            print(f"  env step {step:>6}: RSS {now:8.1f} MB, growth {now - base:+6.2f} MB, "
                  f"longest pose history {longest} (bound {bound}), {step / (time.perf_counter() - start):.0f} steps/s",
                  flush=True)
    if longest > bound:
        raise SystemExit(f"the pose history reached {longest} poses, above its bound {bound}")
    env.close()
    return growth


def soak_estimates(count: int, every: int, n: int, seed: int, method: str) -> list[float]:
    from stereovo import estimate_motion
    from stereovo.simulation import SimulationConfig, simulate_frame

    config = SimulationConfig(n_correspondences=n, outlier_ratio=(0.2, 0.8))
    frames = [simulate_frame(config, np.random.default_rng([seed, i])) for i in range(50)]  # reused: no growth from frames
    for frame in frames[:5]:  # warm-up
        estimate_motion(frame.prev, frame.curr, frame.camera, method=method, rng=0)
    print(f"estimator: {count} estimates of {method}, N {n}")
    base, growth = rss_mb(), []
    start = time.perf_counter()
    for i in range(1, count + 1):
        frame = frames[i % len(frames)]
        estimate_motion(frame.prev, frame.curr, frame.camera, method=method, rng=i)
        if i % every == 0:
            now = rss_mb()
            growth.append(now - base)
            print(f"  estimate {i:>6}: RSS {now:8.1f} MB, growth {now - base:+6.2f} MB, "
                  f"{i / (time.perf_counter() - start):.0f} estimates/s", flush=True)
    return growth


def _per_thousand(growth: list[float], every: int) -> str:
    if len(growth) < 2:
        return "n/a (too few reports)"
    slope = np.polyfit(np.arange(1, len(growth) + 1) * every / 1000, growth, 1)[0]
    return f"{slope:+.3f} MB per 1000 (least-squares slope over {len(growth)} reports)"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=10_000, help="env steps and estimates each (default 10000)")
    parser.add_argument("--every", type=int, default=1000, help="report RSS every this many (default 1000)")
    parser.add_argument("--frames-per-episode", type=int, default=100, help="episode length (default 100)")
    parser.add_argument("--n", type=int, default=200, help="correspondences per frame (default 200)")
    parser.add_argument("--method", default="probabilistic", help="estimator method (default probabilistic)")
    parser.add_argument("--seed", type=int, default=0, help="seed (default 0)")
    args = parser.parse_args(argv)
    if min(args.steps, args.every, args.frames_per_episode) < 1 or args.n < 3:
        parser.error("--steps, --every and --frames-per-episode must be >= 1, --n >= 3")
    env_growth = soak_env(args.steps, args.every, args.frames_per_episode, args.n, args.seed)
    est_growth = soak_estimates(args.steps, args.every, args.n, args.seed, args.method)
    print(f"environment RSS growth: {_per_thousand(env_growth, args.every)}")
    print(f"estimator RSS growth:   {_per_thousand(est_growth, args.every)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
