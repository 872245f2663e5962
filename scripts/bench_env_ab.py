#!/usr/bin/env python
"""Two checkouts of the code under Gymnasium's benchmarks, alternating in one run: the ratios after/before.

Each round starts one child process per checkout (their order alternating between rounds), with
``PYTHONPATH`` set to the checkout; a child (the checkout's own ``scripts/bench_env_gym.cpu_rate``,
present since 241cfdd) warms up (300 steps with their frame ends and resets, which compiles what a
checkout without numba's cache lacks), then measures
for each environment Gymnasium's ``benchmark_step`` (wall clock, random actions from the action space,
resets included) and the process CPU rate of the same loop (steps and frames per CPU-second). The
table gives the medians over rounds and the median of the per-round ratios (after / before), with the
load average before and after. Make the "before" checkout with ``git worktree add /tmp/before
<commit>`` (or ``git archive <commit> | tar -x -C /tmp/before``). Pin the run to one core for the
"one core" figures: ``taskset -c 1 python scripts/bench_env_ab.py --before /tmp/before``.

Usage::

    python scripts/bench_env_ab.py --before DIR [--after DIR] [--rounds 4] [--seconds 2] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

IDS = ("vo_gym/StereoVO-v0", "vo_gym/StereoVOProsac-v0", "vo_gym/StereoVOAdaptive-v0")

CHILD = r"""
import json, sys
import gymnasium as gym
from gymnasium.utils.performance import benchmark_step
import vo_gym  # noqa: F401
sys.path.insert(0, "scripts")  # the checkout's own bench_env_gym (cwd is the checkout)
from bench_env_gym import cpu_rate

seconds, ids = float(sys.argv[1]), sys.argv[2:]
out = {}
for env_id in ids:
    env = gym.make(env_id)
    env.action_space.seed(0)
    # Warm-up by steps, not time: a checkout without numba's cache compiles kernels on their first use,
    # some only at a frame's end or an episode's reset, and a timed warm-up ends after the first one.
    env.reset(seed=0)
    for _ in range(300):
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        if terminated or truncated:
            env.reset()
    benchmark_step(env, target_duration=0.5, seed=0)
    wall = benchmark_step(env, target_duration=seconds, seed=0)
    steps, frames = cpu_rate(env, seconds)
    out[env_id] = {"steps_per_s": wall, "steps_per_cpu_s": steps, "frames_per_cpu_minute": 60 * frames}
    env.close()
print(json.dumps(out))
"""

def run_child(root: Path, seconds: float) -> dict:
    env = {**os.environ, "PYTHONPATH": str(root), "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
           "MKL_NUM_THREADS": "1"}
    done = subprocess.run([sys.executable, "-c", CHILD, str(seconds), *IDS], cwd=root, env=env,
                          capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--before", required=True, type=Path)
    parser.add_argument("--after", type=Path, default=Path(__file__).resolve().parents[1])
    parser.add_argument("--rounds", type=int, default=4)
    parser.add_argument("--seconds", type=float, default=2.0)
    parser.add_argument("--json", default=None)
    args = parser.parse_args()
    load_start = os.getloadavg()
    runs: dict[str, list[dict]] = {"before": [], "after": []}
    for r in range(args.rounds):
        order = ("before", "after") if r % 2 == 0 else ("after", "before")
        for which in order:
            runs[which].append(run_child(getattr(args, which).resolve(), args.seconds))
        print(f"round {r + 1}/{args.rounds} done (load {os.getloadavg()[0]:.1f})", file=sys.stderr)
    load_end = os.getloadavg()
    print(f"load average {load_start[0]:.1f} / {load_start[1]:.1f} / {load_start[2]:.1f} at the start, "
          f"{load_end[0]:.1f} / {load_end[1]:.1f} / {load_end[2]:.1f} at the end; {args.rounds} rounds, "
          f"{args.seconds:g} s a measurement; CPU affinity {sorted(os.sched_getaffinity(0))}")
    print(f"{'environment':<28} {'figure':<22} {'before':>9} {'after':>9} {'after/before (runs)':>30}")
    result = {}
    for env_id in IDS:
        for key in ("steps_per_s", "steps_per_cpu_s", "frames_per_cpu_minute"):
            before = [run[env_id][key] for run in runs["before"]]
            after = [run[env_id][key] for run in runs["after"]]
            ratios = [a / b for a, b in zip(after, before)]
            result[f"{env_id} {key}"] = {"before": before, "after": after, "ratios": ratios}
            print(f"{env_id:<28} {key:<22} {statistics.median(before):>9.0f} {statistics.median(after):>9.0f} "
                  f"{statistics.median(ratios):>8.2f} ({', '.join(f'{x:.2f}' for x in ratios)})")
    if args.json:
        result["load"] = {"start": load_start, "end": load_end}
        Path(args.json).write_text(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
