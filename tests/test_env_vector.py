"""StereoVOEnv under Gymnasium's sync/async vector envs and stable-baselines3's DummyVecEnv/SubprocVecEnv."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import data_equivalence
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

import vo_gym  # noqa: F401  (registers the ids)
from vo_gym import N_FEATURES

N = 80
KWARGS = dict(n_frames=3, n_correspondences=N)


def _run_gym_vector(mode):
    envs = gym.make_vec("vo_gym/StereoVO-v0", num_envs=2, vectorization_mode=mode, **KWARGS)
    try:
        obs, _ = envs.reset(seed=[1, 2])
        assert obs["features"].shape == (2, N, N_FEATURES) and obs["mask"].shape == (2, N)
        trace = [obs]
        ends = []
        for step in range(4):  # crosses the episode end (3 frames) and the autoreset step
            obs, reward, terminated, truncated, info = envs.step(np.zeros((2, N), np.float32))
            assert reward.shape == (2,) and not terminated.any()
            ends.append(truncated.copy())
            trace.append((obs, reward, info))
        return trace, ends
    finally:
        envs.close()


def test_gymnasium_sync_and_async_agree():
    sync, sync_ends = _run_gym_vector("sync")
    asyn, async_ends = _run_gym_vector("async")
    assert [e.tolist() for e in sync_ends] == [[False, False], [False, False], [True, True], [False, False]]
    assert all(np.array_equal(a, b) for a, b in zip(sync_ends, async_ends))
    assert data_equivalence(sync, asyn, exact=True)
    final_info = sync[3][2]
    assert "trajectory" in final_info and final_info["_trajectory"].all()


@pytest.mark.parametrize("vec_cls", [DummyVecEnv, SubprocVecEnv])
def test_sb3_vec_envs(vec_cls):
    # Workers are forked here to keep the test fast (forkserver/spawn workers import torch afresh, ~10 s).
    # Under forkserver/spawn a worker has not imported vo_gym: name the module in the id,
    # "vo_gym:vo_gym/StereoVOProsac-v0" (test_env.py checks that form in a fresh interpreter).
    vec_kwargs = {"start_method": "fork"} if vec_cls is SubprocVecEnv else None
    venv = make_vec_env("vo_gym:vo_gym/StereoVOProsac-v0", n_envs=2, seed=0, env_kwargs=KWARGS, vec_env_cls=vec_cls,
                        vec_env_kwargs=vec_kwargs)
    try:
        obs = venv.reset()
        assert obs["features"].shape == (2, N, N_FEATURES)
        for step in range(3):
            obs, reward, done, infos = venv.step(np.zeros((2, N), np.float32))
        assert done.all()  # truncated after 3 frames, auto-reset by SB3
        assert all("terminal_observation" in info and "trajectory" in info for info in infos)
        assert all(info["TimeLimit.truncated"] for info in infos)
    finally:
        venv.close()
