"""``reset(options=...)``: the environments take no options, so anything but None or an empty dict is refused
(it was accepted and ignored: ``reset(seed=0, options={"foo": 1})`` gave the episode of ``reset(seed=0)``)."""

from __future__ import annotations

import numpy as np
import pytest
from gymnasium.utils.env_checker import data_equivalence

from vo_gym.adaptive_env import StereoVOAdaptiveEnv
from vo_gym.env import StereoVOEnv

SMALL = dict(n_frames=2, n_correspondences=30)


REFUSED = [{"foo": 1}, {"seed": 3}, "x", [1], [], 0, ()]


@pytest.mark.parametrize("cls", [StereoVOEnv, StereoVOAdaptiveEnv])
def test_reset_takes_none_or_an_empty_dict_and_refuses_other_options_naming_them(cls):
    for options in REFUSED:
        env = cls(**SMALL)
        with pytest.raises(ValueError) as err:
            env.reset(seed=0, options=options)
        assert str(err.value) == (f"{cls.__name__}: reset() takes no options (None or an empty dict; the episode is "
                                  f"drawn from the seed alone), got options={options!r}")
        assert env.current_frame is None  # refused before anything was drawn
    plain, empty = cls(**SMALL), cls(**SMALL)
    assert data_equivalence(plain.reset(seed=4), empty.reset(seed=4, options={}))
    action = np.zeros(plain.action_space.shape, np.float32)
    assert data_equivalence(plain.step(action), empty.step(action))


def test_the_images_environment_refuses_them_too_before_rendering_anything(monkeypatch):
    import stereovo.sequences.rendered
    from vo_gym.images_env import StereoVOImagesEnv

    rendered = []
    monkeypatch.setattr(stereovo.sequences.rendered, "RenderedSequence", lambda **kwargs: rendered.append(kwargs))
    env = StereoVOImagesEnv(n_frames=1, max_correspondences=60)
    with pytest.raises(ValueError, match=r"^StereoVOImagesEnv: reset\(\) takes no options .* got options=\{'foo': 1\}$"):
        env.reset(seed=0, options={"foo": 1})
    assert rendered == [] and env.current_frame is None  # nothing rendered, nothing drawn
