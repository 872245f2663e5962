#!/usr/bin/env python
"""Gymnasium's own throughput benchmarks of the environments, and a digest of their streams.

``gymnasium.utils.performance.benchmark_step`` (one env, random actions from the action space,
resets included) on ``vo_gym/StereoVO-v0``, ``vo_gym/StereoVOProsac-v0`` and
``vo_gym/StereoVOAdaptive-v0`` (one step = one in-frame batch), and ``benchmark_vector_step`` on a
sync vector env of ``--num-envs`` copies, each ``--seconds`` long, ``--repeats`` times (median
reported), single-threaded BLAS, after a warm-up. Also printed: frames per CPU-minute (the
training throughput: a frame is a step of the one-shot env, ``frames / steps`` of the adaptive
one), and with ``--digest`` a digest of the adaptive environment's observations, rewards and infos
on fixed seeds (its stream must stay the same when the code gets faster; the padded batch infos
enter it cut to their ``batch_count`` rows, as they were before they were padded).

To compare two versions of the code, run this once in each checkout, alternating, in the same
minutes (``--json`` keeps the figures): a shared machine's speed drifts between runs.

Usage::

    python scripts/bench_env_gym.py [--seconds 3] [--repeats 3] [--num-envs 2] [--digest | --digest-only] [--json FILE]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import hashlib  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402
from gymnasium.utils.performance import benchmark_step, benchmark_vector_step  # noqa: E402

import vo_gym  # noqa: E402,F401  (registers the ids)

IDS = ("vo_gym/StereoVO-v0", "vo_gym/StereoVOProsac-v0", "vo_gym/StereoVOAdaptive-v0")


def adaptive_digest(steps: int = 120) -> str:
    """sha256 (16 hex) of the adaptive env's observations, rewards and infos over ``steps`` random steps."""
    h = hashlib.sha256()
    env = gym.make("vo_gym/StereoVOAdaptive-v0", n_frames=6)
    obs, _ = env.reset(seed=5)
    env.action_space.seed(5)
    rng = np.random.default_rng(1)
    for i in range(steps):
        action = rng.standard_normal(env.action_space.shape).astype(np.float32)
        action[-1] = 1.0 if i % 5 == 4 else -1.0  # stop every fifth step
        obs, reward, term, trunc, info = env.step(action)
        for key in ("features", "mask", "globals"):
            h.update(np.ascontiguousarray(obs[key]).tobytes())
        h.update(np.float64(reward).tobytes())
        count = info.get("batch_count")
        for key in sorted(info):
            if "time" in key or key == "batch_count":
                continue
            value = np.asarray(info[key])
            if key in ("batch_samples", "batch_inliers") and count is not None:
                # the real rows only (and the frame's columns): the digest of the stream before the
                # infos were padded to a fixed shape
                value = value[:count] if key == "batch_samples" else value[:count, : env.unwrapped.current_frame.n]
            h.update(repr(value.tolist()).encode())
        if term or trunc:
            obs, _ = env.reset()
    return h.hexdigest()[:16]


def cpu_rate(env, seconds: float) -> tuple[float, float]:
    """Steps and frames per CPU-second of this process over ``seconds`` of random steps."""
    env.reset(seed=1)
    steps = frames = 0
    start = time.process_time()
    while time.process_time() - start < seconds:
        _, _, term, trunc, info = env.step(env.action_space.sample())
        steps += 1
        frames += int(info.get("frame_done", True))
        if term or trunc:
            env.reset()
    elapsed = time.process_time() - start
    return steps / elapsed, frames / elapsed


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=3.0)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--num-envs", type=int, default=2)
    parser.add_argument("--digest", action="store_true")
    parser.add_argument("--digest-only", action="store_true", help="print the adaptive digest and nothing else")
    parser.add_argument("--json", default=None)
    args = parser.parse_args()
    if args.digest_only:
        print("adaptive digest", adaptive_digest())
        return 0
    result = {}
    for env_id in IDS:
        env = gym.make(env_id)
        env.action_space.seed(0)
        for _ in range(2):  # warm-up: numba's cache, the first frames
            benchmark_step(env, target_duration=0.5, seed=0)
        single = sorted(benchmark_step(env, target_duration=args.seconds, seed=0) for _ in range(args.repeats))
        cpu = sorted(cpu_rate(env, args.seconds) for _ in range(args.repeats))
        env.close()
        mid = args.repeats // 2
        venv = gym.make_vec(env_id, num_envs=args.num_envs, vectorization_mode="sync")
        try:
            vector = sorted(benchmark_vector_step(venv, target_duration=args.seconds, seed=0) for _ in range(args.repeats))
            vector_text = f"{vector[mid]:8.0f} steps/s"
        except ValueError as exc:  # Gymnasium cannot stack infos whose arrays change shape between steps
            vector, vector_text = [float("nan")] * args.repeats, f"not measured ({exc})"
        venv.close()
        result[env_id] = {"steps_per_s": single[mid], "steps_per_s_runs": single,
                          "vector_sync_steps_per_s": vector[mid], "steps_per_cpu_s": cpu[mid][0],
                          "frames_per_cpu_minute": 60 * cpu[mid][1]}
        print(f"{env_id:<28} benchmark_step {single[mid]:8.0f} steps/s (runs {', '.join(f'{x:.0f}' for x in single)}); "
              f"{cpu[mid][0]:8.0f} steps per CPU-s; {60 * cpu[mid][1]:8.0f} frames per CPU-minute; "
              f"sync x{args.num_envs} {vector_text}")
    if args.digest:
        result["adaptive_digest"] = adaptive_digest()
        print("adaptive digest", result["adaptive_digest"])
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(result, fh, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
