"""vo-gym: stereo visual odometry as a Gymnasium environment for learning RANSAC sampling priors.

Importing the package registers the environment ids (:data:`ENV_IDS`: every one)::

    import gymnasium as gym
    import vo_gym

    env = gym.make("vo_gym/StereoVO-v0")

The exports below load on first use, so ``import vo_gym`` (and the ``vo-gym``
command line above it, ``vo_gym_cli``) stays light: only Gymnasium is
imported to register the ids; the simulator and the estimator core load with
the environment.
"""

from __future__ import annotations

import importlib
from typing import Any

from vo_gym.registration import register_envs, registered_ids

register_envs()

ENV_IDS: tuple[str, ...] = registered_ids()
"""Every registered ``vo_gym/`` id, sorted (the step, hard, PROSAC, in-frame adaptive and image ids)."""

_LAZY = {
    "StereoVOEnv": "vo_gym.env",
    "StereoVOAdaptiveEnv": "vo_gym.adaptive_env",
    "StereoVOImagesEnv": "vo_gym.images_env",
    "SAMPLING_MODES": "vo_gym.settings",
    "DEFAULT_ESTIMATOR_OPTIONS": "vo_gym.settings",
    "REWARD_MODES": "vo_gym.rewards",
    "FEATURE_NAMES": "vo_gym.features",
    "FEATURE_LAYOUT_VERSION": "vo_gym.features",
    "N_FEATURES": "vo_gym.features",
    "compute_features": "vo_gym.features",
    "feature_index": "vo_gym.features",
    "check_feature_layout": "vo_gym.features",
}

__all__ = ["ENV_IDS", "register_envs", *_LAZY]


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'vo_gym' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))
