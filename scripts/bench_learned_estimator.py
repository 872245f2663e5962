"""Per-frame cost of agents.LearnedEstimator against the core's MSAC at the same budget.

Loads each sampler once, warms up (numba kernels, torch), then times ``estimate`` over the same
simulated frames (eps 0.8, N 500, 10-frame sequences, one torch thread) and prints the median
milliseconds per frame and the ratio to ``estimate_motion(method="msac", budget=16)`` with the
environments' options on those frames, measured in the same run.

    python scripts/bench_learned_estimator.py [--frames 100]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from agents import LearnedEstimator
from agents.checkpoint import SHIPPED_IN_FRAME_SAMPLERS, SHIPPED_SAMPLERS
from stereovo.estimation import estimate_motion
from stereovo.simulation import Sequence, SimulationConfig
from vo_gym.settings import DEFAULT_ESTIMATOR_OPTIONS


def frames(n: int) -> list[list]:
    config = SimulationConfig(n_frames=10, n_correspondences=500, outlier_ratio=0.8)
    return [list(Sequence(config, seed=np.random.SeedSequence([4242, i]))) for i in range((n + 9) // 10)]


def median_ms(run, sequences) -> tuple[float, float]:
    times, hypotheses = [], []
    for sequence in sequences:
        for est in run(sequence):
            times.append(est.time_s)
            hypotheses.append(est.n_hypotheses)
    return 1e3 * float(np.median(times)), float(np.mean(hypotheses))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=100)
    args = parser.parse_args()
    torch.set_num_threads(1)
    sequences = frames(args.frames)

    def msac(sequence):
        return [estimate_motion(f.prev, f.curr, f.camera, method="msac", budget=16, rng=f.index,
                                **DEFAULT_ESTIMATOR_OPTIONS) for f in sequence]

    msac(sequences[0])  # warm-up: kernels compile or load from the cache
    reference, _ = median_ms(msac, sequences)
    print(f"reference: estimate_motion msac, 16 hypotheses: {reference:.2f} ms per frame (median)")
    for name in SHIPPED_SAMPLERS + SHIPPED_IN_FRAME_SAMPLERS:
        for budget in (16, None):
            start = time.perf_counter()
            estimator = LearnedEstimator(name, budget=budget)
            load_ms = 1e3 * (time.perf_counter() - start)

            def run(sequence, estimator=estimator):
                return estimator.estimate_sequence([(f.prev, f.curr, f.camera, f.scores) for f in sequence])

            run(sequences[0])  # warm-up
            ms, hyp = median_ms(run, sequences)
            stop = "budget 16" if budget else "own stop"
            print(f"{name:32s} {estimator.kind:8s} {stop:9s}: {ms:6.2f} ms per frame ({ms / reference:4.1f}x msac), "
                  f"{hyp:5.1f} hypotheses, loaded in {load_ms:.0f} ms")


if __name__ == "__main__":
    main()
