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


def _plain_episode(seed, actions):
    """Observations, rewards and the last info of one plain env episode under ``actions``."""
    env = gym.make("vo_gym/StereoVOProsac-v0", **KWARGS)
    obs, _ = env.reset(seed=seed)
    trace = [obs]
    rewards, info = [], {}
    for action in actions:
        obs, reward, _, _, info = env.step(action)
        trace.append(obs)
        rewards.append(reward)
    env.close()
    return trace, rewards, info


@pytest.mark.parametrize("vec_cls", [DummyVecEnv, SubprocVecEnv])
def test_sb3_vec_envs_step_exactly_like_the_plain_env(vec_cls):
    # Workers are forked here to keep the test fast (forkserver/spawn workers import torch afresh, ~10 s).
    # Under forkserver/spawn a worker has not imported vo_gym: name the module in the id,
    # "vo_gym:vo_gym/StereoVOProsac-v0" (test_env.py checks that form in a fresh interpreter).
    vec_kwargs = {"start_method": "fork"} if vec_cls is SubprocVecEnv else None
    venv = make_vec_env("vo_gym:vo_gym/StereoVOProsac-v0", n_envs=2, seed=0, env_kwargs=KWARGS, vec_env_cls=vec_cls,
                        vec_env_kwargs=vec_kwargs)
    ramp = np.linspace(-1, 1, N, dtype=np.float32)
    actions = np.stack([np.stack([ramp, -ramp]) * (step + 1) for step in range(3)])  # (steps, envs, N)
    try:
        obs = venv.reset()
        trace, rewards, dones, infos = [obs], [], [], []
        for step in range(3):
            obs, reward, done, info = venv.step(actions[step])
            trace.append(obs)
            rewards.append(reward)
            dones.append(done)
            infos.append(info)
    finally:
        venv.close()
    assert [d.tolist() for d in dones] == [[False, False], [False, False], [True, True]]
    # SB3 seeds env i with seed + i: each worker replays the plain env's episode bit for bit.
    for i in range(2):
        plain, plain_rewards, plain_info = _plain_episode(i, actions[:, i])
        for k in range(3):  # the reset observation and the two steps before the end
            for key in ("features", "mask"):
                np.testing.assert_array_equal(trace[k][key][i], plain[k][key])
        np.testing.assert_array_equal(np.float32([r[i] for r in rewards]), np.float32(plain_rewards))  # SB3 may cast
        final = infos[-1][i]
        assert final["TimeLimit.truncated"]  # truncated, not terminated, then auto-reset by SB3
        for key in ("features", "mask"):
            np.testing.assert_array_equal(final["terminal_observation"][key], plain[3][key])
        assert final["trajectory"] == plain_info["trajectory"]
    assert not np.array_equal(trace[1]["features"][0], trace[1]["features"][1])  # two different episodes
