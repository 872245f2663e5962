"""Print SHA-256 digests of simulated frames, estimates and environment episodes.

A developer's check that a change is bit for bit: run it before and after and
compare the three lines (``python scripts/digests.py``). Times are left out. Compare digests made on
the same kind of CPU: numpy's float64 ``exp`` and ``log`` are vectorised where the CPU has AVX-512 and
differ there from the C library's in the last bit, so estimates that use them (MLESAC's likelihood, the
features) hash differently on such a machine (e.g. an AMD EPYC against an Intel one without AVX-512).
"""

from __future__ import annotations

import hashlib

import gymnasium
import numpy as np

import vo_gym  # noqa: F401  (registers the ids)
from stereovo.estimation import available_methods, estimate_motion
from stereovo.simulation import SimulationConfig, simulate_frame


def _update(h, *arrays) -> None:
    for a in arrays:
        h.update(np.ascontiguousarray(np.asarray(a, dtype=float)).tobytes())


def frame_digest() -> tuple[str, list]:
    h = hashlib.sha256()
    frames = []
    for i, kw in enumerate([{}, {"outlier_ratio": 0.8}, {"n_correspondences": 200, "outlier_ratio": 0.5}]):
        f = simulate_frame(SimulationConfig(**kw), rng=100 + i)
        _update(h, f.prev, f.curr, f.scores, f.truth.inlier, f.truth.rotation, f.truth.translation)
        frames.append(f)
    return h.hexdigest()[:16], frames


def estimate_digest(frames) -> str:
    h = hashlib.sha256()
    for name in sorted(available_methods()):
        for f in frames:
            kw = {}
            if name in ("prosac",):
                kw["order"] = np.argsort(-f.scores, kind="stable")
            if name in ("guided-mlesac",):
                kw["priors"] = f.scores
            try:
                est = estimate_motion(f.prev, f.curr, f.camera, method=name, rng=7, **kw)
            except Exception as err:  # a method that needs inputs we did not give
                h.update(f"{name}:{type(err).__name__}".encode())
                continue
            _update(h, est.rotation, est.translation, est.inliers, [est.n_hypotheses, est.n_scored])
            h.update(est.status.encode())
    return h.hexdigest()[:16]


def env_digest() -> str:
    h = hashlib.sha256()
    for env_id in ("vo_gym/StereoVO-v0", "vo_gym/StereoVOProsac-v0", "vo_gym/StereoVOHard-v0"):
        env = gymnasium.make(env_id, max_episode_steps=15)
        obs, info = env.reset(seed=3)
        rng = np.random.default_rng(0)
        _update(h, obs["features"], obs["mask"])
        for _ in range(15):
            action = rng.standard_normal(env.action_space.shape).astype(np.float32)
            obs, reward, term, trunc, info = env.step(action)
            _update(h, obs["features"], obs["mask"], [reward, term, trunc])
            for key in sorted(info):
                value = info[key]
                if "time" in key:
                    continue
                if isinstance(value, (int, float, np.ndarray, np.number, bool)):
                    _update(h, np.ravel(value))
                else:
                    h.update(repr(value).encode())
            if term or trunc:
                break
        env.close()
    return h.hexdigest()[:16]


def main() -> None:
    import argparse

    argparse.ArgumentParser(description=__doc__.split("\n\n")[0]).parse_args()  # --help, and no stray arguments
    frames_hex, frames = frame_digest()
    print("frames   ", frames_hex)
    print("estimates", estimate_digest(frames))
    print("env      ", env_digest())


if __name__ == "__main__":
    main()
