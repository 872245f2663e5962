#!/usr/bin/env python
"""Environment steps per second of vo_gym.StereoVOEnv: one env, and Gymnasium's sync / async vector envs.

Usage::

    .venv/bin/python scripts/bench_env.py                  # N = 500, budget 32, 500 steps each
    .venv/bin/python scripts/bench_env.py --steps 2000 --num-envs 4 --json bench_env.json
    .venv/bin/python scripts/bench_env.py --pin-workers    # async workers pinned to cores (Linux)

Every process runs single-threaded BLAS (set before numpy loads), so "per core"
is literal: the single env and the sync vector env run in this one process;
the async vector env runs ``--num-envs`` worker processes and its per-core
figure divides by ``min(num_envs, cores available)``. The action is uniform
(zeros: every correspondence equally likely), which costs the same as any other
action. Each mode is timed ``--repeats`` times and the median run reported
(all runs are in the JSON). A breakdown of one step (simulation, features,
estimator; medians over an episode's frames, after a warm-up pass) is
printed too. On a shared machine run it when the machine is otherwise idle.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402

import vo_gym  # noqa: E402,F401  (registers the ids)
from stereovo.estimation import estimate_motion  # noqa: E402
from vo_gym.features import compute_features  # noqa: E402


def _env_kwargs(args) -> dict:
    return dict(n_correspondences=args.n, budget=args.budget, n_frames=args.n_frames)


def _median_rate(runs: list[tuple[int, float]]) -> tuple[int, float]:
    """The run with the median rate: (steps, seconds)."""
    return sorted(runs, key=lambda r: r[0] / r[1])[len(runs) // 2]


def bench_single(args) -> dict:
    env = gym.make(args.id, **_env_kwargs(args))
    env.reset(seed=0)
    action = np.zeros(env.action_space.shape, np.float32)
    for _ in range(args.warmup):
        if env.step(action)[3]:
            env.reset()
    runs, cpu = [], []
    for _ in range(args.repeats):
        start, cpu_start = time.perf_counter(), time.process_time()
        for _ in range(args.steps):
            if env.step(action)[3]:
                env.reset()
        runs.append((args.steps, time.perf_counter() - start))
        cpu.append(time.process_time() - cpu_start)
    env.close()
    steps, elapsed = _median_rate(runs)
    rates = [r[0] / r[1] for r in runs]
    cpu_seconds = float(np.median(cpu))
    return {"steps": steps, "seconds": elapsed, "steps_per_s": steps / elapsed,
            "steps_per_s_per_core": steps / elapsed, "cores": 1, "steps_per_cpu_s": steps / cpu_seconds,
            "cpu_seconds": cpu_seconds, "all_runs_steps_per_s": rates}


def _cpu_seconds(pids: list[int]) -> float:
    """CPU time (user + system, s) of this process and of the worker processes ``pids``.

    Workers are read from ``/proc/<pid>/stat``; NaN where that is unavailable (not Linux).
    """
    total = time.process_time()
    for pid in pids:
        try:
            with open(f"/proc/{pid}/stat") as fh:
                fields = fh.read().rsplit(")", 1)[1].split()
            total += (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")  # utime, stime
        except (OSError, IndexError, ValueError):
            return float("nan")
    return total


def _pin(pids: list[int]) -> None:
    """Pin worker ``i`` to the ``i``-th available core (round robin); the main process stays free.

    A worker that waits at the step barrier and then wakes on another core finds its caches
    cold: on a 2-core machine its CPU time per step rose by up to half over a lone env's.
    """
    if not hasattr(os, "sched_setaffinity"):
        raise SystemExit("bench_env: --pin-workers needs os.sched_setaffinity (Linux)")
    cores = sorted(os.sched_getaffinity(0))
    for i, pid in enumerate(pids):
        os.sched_setaffinity(pid, {cores[i % len(cores)]})


def bench_vector(args, mode: str) -> dict:
    envs = gym.make_vec(args.id, num_envs=args.num_envs, vectorization_mode=mode, **_env_kwargs(args))
    envs.reset(seed=0)
    action = np.zeros(envs.action_space.shape, np.float32)  # autoreset handles episode ends
    for _ in range(max(1, args.warmup // args.num_envs)):
        envs.step(action)
    n_calls = max(1, args.steps // args.num_envs)
    pids = [p.pid for p in getattr(envs, "processes", [])]
    if mode == "async" and args.pin_workers:
        _pin(pids)
    runs, cpu = [], []
    for _ in range(args.repeats):
        start, cpu_start = time.perf_counter(), _cpu_seconds(pids)
        for _ in range(n_calls):
            envs.step(action)
        runs.append((n_calls * args.num_envs, time.perf_counter() - start))
        cpu.append(_cpu_seconds(pids) - cpu_start)
    envs.close()
    steps, elapsed = _median_rate(runs)
    available = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    cores = 1 if mode == "sync" else min(args.num_envs, available)
    cpu_seconds = float(np.median(cpu))
    return {"num_envs": args.num_envs, "pinned": bool(mode == "async" and args.pin_workers),
            "steps": steps, "seconds": elapsed, "steps_per_s": steps / elapsed,
            "steps_per_s_per_core": steps / elapsed / cores, "cores": cores,
            "steps_per_cpu_s": steps / cpu_seconds, "cpu_seconds": cpu_seconds,
            "all_runs_steps_per_s": [r[0] / r[1] for r in runs]}


def bench_breakdown(args) -> dict:
    """Median milliseconds of the parts of a step, on the frames of one episode."""
    env = gym.make(args.id, **_env_kwargs(args)).unwrapped
    env.reset(seed=1)
    frames = [env.sequence.frame(k) for k in range(1, min(args.n_frames, 50) + 1)]
    sim, feat, est = [], [], []
    rng = np.random.default_rng(0)
    for frame in frames + frames:  # the first pass warms up; only the second is kept
        t0 = time.perf_counter()
        env.sequence.frame(frame.index)
        t1 = time.perf_counter()
        compute_features(frame.prev, frame.curr, frame.scores, frame.camera, env.estimator_noise_sigma, None)
        t2 = time.perf_counter()
        estimate_motion(frame.prev, frame.curr, frame.camera, method=env.method, priors=np.ones(frame.n),
                        rng=rng, **env.estimator_kwargs)
        t3 = time.perf_counter()
        sim.append(t1 - t0), feat.append(t2 - t1), est.append(t3 - t2)
    keep = slice(len(frames), None)
    return {name: 1e3 * float(np.median(v[keep])) for name, v in (("simulation_ms", sim), ("features_ms", feat),
                                                                 ("estimator_ms", est))}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--id", default="vo_gym/StereoVO-v0", help="environment id")
    parser.add_argument("--n", type=int, default=500, help="correspondences per frame")
    parser.add_argument("--budget", type=int, default=32, help="hypotheses per frame")
    parser.add_argument("--n-frames", type=int, default=100, help="frames per episode")
    parser.add_argument("--steps", type=int, default=500, help="environment steps per measurement")
    parser.add_argument("--warmup", type=int, default=20, help="untimed steps first")
    parser.add_argument("--repeats", type=int, default=3, help="timed runs per mode; the median is reported")
    parser.add_argument("--num-envs", type=int, default=2, help="envs of the vector envs (async: worker processes)")
    parser.add_argument("--pin-workers", action="store_true",
                        help="pin each async worker process to its own core (Linux), as a training launcher may")
    parser.add_argument("--target", type=float, default=200.0,
                        help="steps/s per core each mode should reach (the issue's target); printed as met or missed")
    parser.add_argument("--json", help="also write the results to this file")
    args = parser.parse_args(argv)

    results = {
        "setting": {"id": args.id, "n_correspondences": args.n, "budget": args.budget,
                    "method": gym.make(args.id).unwrapped.method, "python": platform.python_version(),
                    "numpy": np.__version__, "machine": platform.machine(), "cpus": os.cpu_count()},
        "single": bench_single(args),
        "breakdown": bench_breakdown(args),
        "sync": bench_vector(args, "sync"),
        "async": bench_vector(args, "async"),
    }
    s = results["setting"]
    print(f"{s['id']}: N = {s['n_correspondences']}, budget {s['budget']} hypotheses, method {s['method']}, "
          f"single-threaded BLAS, {s['cpus']} CPUs")
    b = results["breakdown"]
    print(f"one step (median): simulation {b['simulation_ms']:.2f} ms, features {b['features_ms']:.2f} ms, "
          f"estimator {b['estimator_ms']:.2f} ms")
    # steps/s/core divides wall-clock throughput by the cores the mode occupies; steps/cpu-s divides
    # the steps by the CPU time all its processes (main and workers) actually spent, which leaves
    # out the time a worker waits at the vector env's step barrier for the other one.
    print(f"{'mode':<8}{'envs':>5}{'cores':>6}{'steps':>7}{'steps/s':>10}{'steps/s/core':>14}{'steps/cpu-s':>13}")
    for mode in ("single", "sync", "async"):
        r = results[mode]
        label = mode + ("*" if r.get("pinned") else "")
        print(f"{label:<8}{r.get('num_envs', 1):>5}{r['cores']:>6}{r['steps']:>7}{r['steps_per_s']:>10.1f}"
              f"{r['steps_per_s_per_core']:>14.1f}{r['steps_per_cpu_s']:>13.1f}")
    if results["async"].get("pinned"):
        print("* workers pinned to their own cores (--pin-workers)")
    verdicts = {mode: results[mode]["steps_per_s_per_core"] >= args.target for mode in ("single", "sync", "async")}
    results["target_steps_per_s_per_core"] = args.target
    results["target_met"] = verdicts
    print(f"target >= {args.target:g} steps/s per core: "
          + ", ".join(f"{mode} {'met' if ok else 'MISSED'}" for mode, ok in verdicts.items()))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(results, fh, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
