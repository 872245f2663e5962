#!/usr/bin/env python
"""Steps per second of ``vo_gym/StereoVOImages-v0`` against ``vo_gym/StereoVO-v0``, in one run.

A step of the images environment renders the next stereo pair, detects and matches it (the
front end, streaming), builds the observation and runs the estimator; a second pass over the same
seed, whose frames are kept (what the seed determines is cached), is timed too ("replaying a cached
seed").
One process, single-threaded OpenCV, numba and BLAS; llvmpipe's threads follow
``LP_NUM_THREADS``. The action is uniform (zeros).

    PYTHONPATH=. python scripts/bench_images_env.py [--steps 60] [--resolution kitti]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402


def _run(env, seed: int, steps: int) -> float:
    env.reset(seed=seed)
    action = np.zeros(env.action_space.shape, np.float32)
    start = time.perf_counter()
    done = 0
    while done < steps:
        _, _, terminated, truncated, _ = env.step(action)
        done += 1
        if terminated or truncated:
            env.reset(seed=seed)
    return steps / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=60)
    parser.add_argument("--resolution", default="kitti", choices=("kitti", "vga"))
    args = parser.parse_args()
    import cv2
    import gymnasium as gym
    import numba

    import vo_gym  # noqa: F401

    cv2.setNumThreads(1)
    numba.set_num_threads(1)
    images = gym.make("vo_gym/StereoVOImages-v0", n_frames=args.steps, resolution=args.resolution).unwrapped
    simulated = gym.make("vo_gym/StereoVO-v0", n_frames=args.steps).unwrapped
    _run(images, 99, 3)  # compile and warm
    _run(simulated, 99, 3)
    fresh = _run(images, 0, args.steps)
    replay = _run(images, 0, args.steps)
    sim = _run(simulated, 0, args.steps)
    print(f"StereoVOImages-v0 ({args.resolution}, budget {images.budget}, up to {images.max_correspondences} rows): "
          f"{fresh:.1f} steps/s rendering and matching; {replay:.1f} steps/s replaying a cached seed")
    print(f"StereoVO-v0 (simulated, N {simulated.n_correspondences}): {sim:.1f} steps/s; "
          f"images / simulated = {fresh / sim:.3f}x")
    images.close()


if __name__ == "__main__":
    main()
