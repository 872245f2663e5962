"""Rolling a sampling policy through the environment: the small loop that trainers and evaluation share.

:func:`success_rate` is what the PPO trainer's evaluation callback
(:mod:`agents.ppo.train`) measures on its held-out seeds, and :func:`make_env` what
:mod:`agents.evaluation.run` steps; it sits below both so that neither imports the other for it.
"""

from __future__ import annotations

from typing import Any, Mapping, Sequence

import numpy as np

from agents.policies import Policy

__all__ = ["make_env", "success_rate"]


def make_env(env_id: str, **kwargs: Any):
    """``gymnasium.make(env_id, **kwargs)`` with the vo_gym ids registered.

    Raises:
        ValueError: Gymnasium refused the id or the keyword arguments (its message, prefixed by the id).
    """
    import gymnasium as gym

    import vo_gym  # registers the ids
    from vo_gym.names import did_you_mean

    try:
        return gym.make(env_id, **kwargs)
    except gym.error.Error as err:
        known = env_id in vo_gym.ENV_IDS or "did you mean" in str(err).lower()
        hint = "" if known else did_you_mean(env_id, vo_gym.ENV_IDS)
        raise ValueError(f"environment {env_id!r}: {err}{hint}") from None


def success_rate(
    policy: Policy, env_id: str, env_kwargs: Mapping[str, Any], seeds: Sequence[int]
) -> tuple[float, float]:
    """``(frame success rate, mean reward)`` of ``policy`` over one episode from each of ``seeds``.

    Each episode runs in a fresh environment ``make_env(env_id, **env_kwargs)`` reset with its seed,
    in this process; both numbers are means over all frames of all episodes.
    """
    successes: list[bool] = []
    rewards: list[float] = []
    for seed in seeds:
        env = make_env(env_id, **env_kwargs)
        try:
            obs, _ = env.reset(seed=seed)
            done = False
            while not done:
                obs, reward, terminated, truncated, info = env.step(policy.act(obs))
                successes.append(bool(info["success"]))
                rewards.append(float(reward))
                done = terminated or truncated
        finally:
            env.close()
    return float(np.mean(successes)), float(np.mean(rewards))
