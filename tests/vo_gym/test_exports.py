"""The package's lazy exports (``vo_gym/__init__.py``): every name resolves, and every environment
class an id registers is among them, so ``help(vo_gym.<Class>)`` works after ``import vo_gym``."""

from __future__ import annotations

import gymnasium as gym

import vo_gym


def test_every_exported_name_resolves():
    for name in vo_gym.__all__:
        assert getattr(vo_gym, name) is not None, name


def test_every_registered_environment_class_is_exported():
    for env_id in vo_gym.ENV_IDS:
        entry_point = gym.spec(env_id).entry_point
        cls = gym.envs.registration.load_env_creator(entry_point) if isinstance(entry_point, str) else entry_point
        assert cls.__name__ in vo_gym.__all__, (env_id, cls.__name__)
        assert getattr(vo_gym, cls.__name__) is cls
