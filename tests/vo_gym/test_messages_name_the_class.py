"""The environments' error messages start with the name of the class the user made: the images
environment's keywords that its base class checks (``budget``, ``method``, ...) once said
``StereoVOEnv:``, and so did a user's own subclass of either base class."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import vo_gym  # noqa: F401  (registers the ids)
from vo_gym.adaptive_env import StereoVOAdaptiveEnv
from vo_gym.env import StereoVOEnv
from vo_gym.images_env import StereoVOImagesEnv

# each registered id's class, by name: what its messages must start with
CLASS_OF = {
    "vo_gym/StereoVO-v0": "StereoVOEnv",
    "vo_gym/StereoVOProsac-v0": "StereoVOEnv",
    "vo_gym/StereoVOHard-v0": "StereoVOEnv",
    "vo_gym/StereoVOProsacHard-v0": "StereoVOEnv",
    "vo_gym/StereoVOAdaptive-v0": "StereoVOAdaptiveEnv",
    "vo_gym/StereoVOAdaptiveHard-v0": "StereoVOAdaptiveEnv",
    "vo_gym/StereoVOImages-v0": "StereoVOImagesEnv",
}


def test_every_registered_id_is_listed():
    assert set(CLASS_OF) == set(vo_gym.registration.registered_ids())


@pytest.mark.parametrize("env_id", sorted(CLASS_OF))
def test_a_bad_keyword_of_make_names_the_ids_class(env_id):
    with pytest.raises(ValueError) as err:
        gym.make(env_id, hypothesis_cost=2)
    assert str(err.value) == f"{CLASS_OF[env_id]}: hypothesis_cost must be a finite number in [0, 1], got 2"


@pytest.mark.parametrize("kwargs, error, message", [
    ({"budget": -3}, ValueError, "StereoVOImagesEnv: budget must be None or an integer >= 1"),
    ({"method": "nope"}, ValueError, "StereoVOImagesEnv: method: unknown method 'nope'"),
    ({"reward_mode": "x"}, ValueError, "StereoVOImagesEnv: reward_mode must be one of "),
    ({"sampling": "prosac", "logit_scale": 2.0}, ValueError, "StereoVOImagesEnv: logit_scale must be 1 with sampling="),
    ({"confidence": 0.5}, ValueError, "StereoVOImagesEnv: confidence=0.5 would be ignored"),
    ({"kitti_lengths": []}, ValueError, "StereoVOImagesEnv: kitti_lengths must be a non-empty list"),
    ({"reward_mod": "x"}, TypeError, "StereoVOImagesEnv got unexpected keyword argument(s) ['reward_mod']"),
])
def test_the_images_environments_keywords_checked_by_its_base_class_name_it(kwargs, error, message):
    with pytest.raises(error) as err:
        gym.make("vo_gym/StereoVOImages-v0", n_frames=2, max_correspondences=60, **kwargs)
    assert str(err.value).startswith(message), str(err.value)
    assert "StereoVOEnv" not in str(err.value)


def test_a_mistyped_keyword_of_the_images_environment_gets_its_own_keywords_as_hints():
    with pytest.raises(TypeError, match=r"'resolutoin' \(did you mean 'resolution'\?\)"):
        gym.make("vo_gym/StereoVOImages-v0", resolutoin="vga")


def test_the_images_environments_steps_and_resets_name_it():
    env = StereoVOImagesEnv(n_frames=2, max_correspondences=60)
    with pytest.raises(RuntimeError, match=r"^StereoVOImagesEnv: call reset\(\) before step\(\)$"):
        env.step(np.zeros(60, np.float32))
    with pytest.raises(ValueError, match=r"^StereoVOImagesEnv: reset\(\) takes no options "):
        env.reset(options={"a": 1})


class MyStepEnv(StereoVOEnv):
    pass


class MyAdaptiveEnv(StereoVOAdaptiveEnv):
    pass


@pytest.mark.parametrize("cls", [MyStepEnv, MyAdaptiveEnv])
def test_a_users_subclass_is_named_in_the_constructors_messages(cls):
    with pytest.raises(ValueError, match=f"^{cls.__name__}: hypothesis_cost must be"):
        cls(hypothesis_cost=2)
    with pytest.raises(ValueError, match=f"^{cls.__name__}: invalid simulator setting"):
        cls(outliers="nope")
    with pytest.raises(ValueError, match=f"^{cls.__name__}: max_correspondences=5 is smaller"):
        cls(n_correspondences=10, max_correspondences=5)


@pytest.mark.parametrize("cls", [MyStepEnv, MyAdaptiveEnv])
def test_a_users_subclass_is_named_in_the_steps_messages(cls):
    env = cls(n_frames=1, n_correspondences=20)
    name = cls.__name__
    size = env.action_space.shape[0]
    with pytest.raises(RuntimeError, match=rf"^{name}: call reset\(\) before step\(\)$"):
        env.step(np.zeros(size, np.float32))
    with pytest.raises(ValueError, match=rf"^{name}: reset\(\) takes no options "):
        env.reset(options={"a": 1})
    env.reset(seed=0)
    with pytest.raises(ValueError, match=rf"^{name}: the action must have shape \({size},\)"):
        env.step(np.zeros(size + 1, np.float32))
    nan = np.zeros(size, np.float32)
    nan[:] = np.nan
    with pytest.raises(ValueError, match=rf"^{name}: the action has NaN or inf in "):
        env.step(nan)
    stop = np.zeros(size, np.float32)
    stop[-1] = 1.0  # the adaptive environment's stop; a logit of 1 in the step environment's last slot
    truncated = False
    while not truncated:
        truncated = env.step(stop)[3]
    with pytest.raises(RuntimeError, match=rf"^{name}: the episode is over \(truncated\); call reset\(\)$"):
        env.step(stop)
