"""StereoVOImagesEnv's arguments checked at construction, without rendering: the rendered world's settings by
RenderedSequence's own rules (``speed=50`` failed only at the first reset), and ``camera`` refused as the
other simulator-only keywords are (it raised "got multiple values for keyword argument 'camera'")."""

from __future__ import annotations

import gymnasium as gym
import pytest

import vo_gym  # noqa: F401  (registers the ids)
from stereovo.camera import StereoCamera
from vo_gym.images_env import StereoVOImagesEnv

SMALL = dict(n_frames=2, max_correspondences=60)


@pytest.mark.parametrize("speed", [50, 0, -0.0, 10.5, float("nan"), True, "fast"])
def test_a_render_speed_outside_the_rendered_sequences_rule_is_refused_by_make(speed):
    from stereovo.sequences.rendered import RENDER_RULES

    with pytest.raises(ValueError) as err:
        gym.make("vo_gym/StereoVOImages-v0", **SMALL, speed=speed)
    with pytest.raises(ValueError) as rule:
        RENDER_RULES["speed"].check("speed", speed, prefix="StereoVOImagesEnv: ")
    assert str(err.value).startswith(str(rule.value)), str(err.value)
    assert str(rule.value).startswith("StereoVOImagesEnv: speed must be None or a finite number in (0, 10] (m/frame), got ")


def test_the_rendered_worlds_settings_and_length_are_checked_before_the_first_reset():
    assert StereoVOImagesEnv(**SMALL, speed=10.0).render_settings["speed"] == 10.0
    with pytest.raises(ValueError, match=r"^StereoVOImagesEnv: world must be None or one of 'street', 'open', got 'moon'"):
        StereoVOImagesEnv(**SMALL, world="moon")
    # an episode renders n_frames + 1 frame pairs, and RenderedSequence renders at most 100000
    with pytest.raises(ValueError, match=r"^StereoVOImagesEnv: n_frames must be at most 99999 for the rendered world"):
        StereoVOImagesEnv(n_frames=100_000, max_correspondences=60)
    StereoVOImagesEnv(n_frames=99_999, max_correspondences=60)  # made; nothing is rendered before reset


@pytest.mark.parametrize("camera", [None, StereoCamera()])
def test_camera_is_refused_like_the_other_simulator_only_keywords(camera):
    with pytest.raises(TypeError) as err:
        gym.make("vo_gym/StereoVOImages-v0", **SMALL, camera=camera)
    assert "StereoVOImagesEnv: ['camera'] are simulator settings; on images the front end decides them (and the " \
           "camera is the resolution's or the source's)" in str(err.value)


@pytest.mark.parametrize("kwargs, message", [
    ({"source": 5}, "StereoVOImagesEnv: source must be a frame sequence with known poses (true_poses), got 5: "),
    ({"source": 0.5}, "StereoVOImagesEnv: source must be a frame sequence with known poses (true_poses), got 0.5: "),
    ({"frontend_options": "n_features=500"},
     "StereoVOImagesEnv: frontend_options must be a dict of FrontendOptions fields, got 'n_features=500'"),
    ({"frontend_options": float("nan")}, "StereoVOImagesEnv: frontend_options must be a dict of FrontendOptions "
                                         "fields, got nan"),
])
def test_a_source_or_frontend_options_of_the_wrong_kind_is_named_with_its_value(kwargs, message):
    # they named the value's type alone ("got int"), not the value
    with pytest.raises(ValueError) as err:
        gym.make("vo_gym/StereoVOImages-v0", **SMALL, **kwargs)
    assert str(err.value).startswith(message), str(err.value)
