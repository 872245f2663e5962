"""The action matters: oracle > uniform > adversarial on the same seeds; the README example runs."""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

import numpy as np
import pytest

from vo_gym import StereoVOEnv

SEEDS = (0, 1)
SETTING = dict(n_frames=10, n_correspondences=300, outlier_ratio=0.75, outlier_mix=(0.5, 0.2, 0.3))


def _oracle(env, obs):  # test-only: reads the hidden labels
    return np.where(env.current_frame.truth.inlier, 10.0, -10.0)


def _uniform(env, obs):
    return np.zeros(env.action_space.shape)


def _adversarial(env, obs):
    return -_oracle(env, obs)


def _evaluate(agent, sampling):
    rewards, successes = [], []
    for seed in SEEDS:
        env = StereoVOEnv(sampling=sampling, **SETTING)
        obs, _ = env.reset(seed=seed)
        truncated = False
        while not truncated:
            obs, reward, _, truncated, info = env.step(agent(env, obs))
            rewards.append(reward)
            successes.append(info["success"])
    return float(np.mean(rewards)), float(np.mean(successes))


@pytest.mark.parametrize("sampling", ["guided", "prosac"])
def test_oracle_beats_uniform_beats_adversarial(sampling):
    oracle, uniform, adversarial = (_evaluate(agent, sampling) for agent in (_oracle, _uniform, _adversarial))
    # (mean reward, success rate) of each agent on the same trajectories
    assert oracle[1] >= 0.95 and oracle[0] > 0.8
    assert oracle[0] > uniform[0] + 0.3 and oracle[1] > uniform[1] + 0.3
    assert uniform[0] > adversarial[0] + 0.1 and uniform[1] >= adversarial[1]
    assert adversarial[1] <= 0.1


def _readme_example() -> str:
    """The environment example of the README, read from the README so the two never drift apart."""
    text = (Path(__file__).resolve().parents[1] / "README.md").read_text()
    block = text.split("<!-- env-example -->", 1)[1]
    return block.split("```python", 1)[1].split("```", 1)[0]


def test_readme_example():
    out, namespace = io.StringIO(), {}
    with contextlib.redirect_stdout(out):
        exec(compile(_readme_example(), "README example", "exec"), namespace)
    assert namespace["truncated"]  # the loop ran exactly one episode
    text = out.getvalue().strip()
    assert text.startswith("success rate ")
    assert float(text.split()[-1]) >= 0.6  # the heuristic clearly beats uniform sampling (about 0.3 here)
