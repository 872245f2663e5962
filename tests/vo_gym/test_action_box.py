"""vo_gym.action_box.ActionBox: Box.sample's draws, bit for bit, in one generator call."""

from __future__ import annotations

import pickle

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces
from gymnasium.vector.utils import batch_space

from vo_gym.action_box import ActionBox

BOXES = [
    dict(low=-10.0, high=10.0, shape=(500,), dtype=np.float32),
    dict(low=-1.0, high=1.0, shape=(7, 3), dtype=np.float32),
    dict(low=np.array([-1.0, 0.0, 2.5]), high=np.array([1.0, 1e-3, 3.0]), dtype=np.float64),
    dict(low=-np.inf, high=1.0, shape=(5,), dtype=np.float32),  # not bounded: Box.sample itself
    dict(low=np.array([-np.inf, 0.0], np.float32), high=np.array([np.inf, 1.0], np.float32), dtype=np.float32),
    dict(low=0, high=5, shape=(4,), dtype=np.int64),  # not float: Box.sample itself
]


@pytest.mark.parametrize("kwargs", BOXES)
def test_samples_and_generator_states_are_box_samples(kwargs):
    ours, theirs = ActionBox(**kwargs), spaces.Box(**kwargs)
    ours.seed(3)
    theirs.seed(3)
    for _ in range(20):
        a, b = ours.sample(), theirs.sample()
        assert a.dtype == b.dtype and a.shape == b.shape
        np.testing.assert_array_equal(a, b)
        assert ours.np_random.bit_generator.state == theirs.np_random.bit_generator.state
        assert ours.contains(a)


def test_it_is_a_box_for_gymnasium():
    ours = ActionBox(-10.0, 10.0, shape=(6,), dtype=np.float32)
    assert isinstance(ours, spaces.Box) and ours == spaces.Box(-10.0, 10.0, shape=(6,), dtype=np.float32)
    batched = batch_space(ours, 3)
    assert batched.shape == (3, 6) and isinstance(batched, spaces.Box)
    again = pickle.loads(pickle.dumps(ours))
    assert isinstance(again, ActionBox) and again == ours
    again.seed(1)
    ours.seed(1)
    np.testing.assert_array_equal(again.sample(), ours.sample())
    with pytest.raises(gym.error.Error, match="mask"):
        ours.sample(mask=np.ones(6))  # Box.sample's own refusal


@pytest.mark.parametrize("env_id", ["vo_gym/StereoVO-v0", "vo_gym/StereoVOAdaptive-v0"])
def test_the_environments_act_in_an_action_box(env_id):
    import vo_gym  # noqa: F401

    env = gym.make(env_id, n_frames=3)
    assert type(env.action_space) is ActionBox
    env.close()


def test_clipped_finite_is_numpys_clip_times_the_scale():
    from vo_gym.action_box import clipped_finite

    rng = np.random.default_rng(8)
    for trial in range(300):
        n = int(rng.integers(0, 600))
        x = rng.standard_normal(n) * 10.0 ** rng.integers(-3, 4)
        if n:
            x[rng.integers(0, n, 4)] = rng.choice([0.0, -0.0, 10.0, -10.0, np.nextafter(10, 11), 1e308, -1e308], 4)
        if trial % 5 == 0:
            x = np.repeat(x, 2)[::2]  # a strided view
        bound, scale = float(rng.choice([10.0, 1.0, 0.5])), float(rng.choice([1.0, 10.0, 0.3]))
        ours = clipped_finite(x, bound, scale)
        want = np.minimum(np.maximum(x, -bound), bound) * scale
        assert ours.dtype == want.dtype and ours.tobytes() == want.tobytes()
    for bad in (np.nan, np.inf, -np.inf):
        assert clipped_finite(np.array([0.0, bad, 1.0]), 10.0) is None


def test_clipped_finite_reads_float32_as_its_float64_cast():
    from vo_gym.action_box import clipped_finite

    rng = np.random.default_rng(9)
    for trial in range(300):
        n = int(rng.integers(0, 600))
        x = (rng.standard_normal(n) * 10.0 ** rng.integers(-3, 4)).astype(np.float32)
        if n:
            x[rng.integers(0, n, 4)] = rng.choice([0.0, -0.0, 10.0, -10.0, np.nextafter(np.float32(10), 11), 3e38], 4)
        if trial % 5 == 0:
            x = np.repeat(x, 2)[::2]
        bound, scale = float(rng.choice([10.0, 1.0, 0.5])), float(rng.choice([1.0, 10.0, 0.3]))
        ours, want = clipped_finite(x, bound, scale), clipped_finite(x.astype(np.float64), bound, scale)
        assert ours.dtype == np.float64 and ours.tobytes() == want.tobytes()
    for bad in (np.nan, np.inf, -np.inf):
        assert clipped_finite(np.array([0.0, bad, 1.0], dtype=np.float32), 10.0) is None


def test_exp_shifted_is_numpys_softmax_numerator():
    from vo_gym.action_box import exp_shifted

    rng = np.random.default_rng(11)
    for trial in range(400):
        n = int(rng.integers(1, 600))
        x = rng.uniform(-10, 10, n) * rng.choice([1.0, 1e-3, 30.0])
        if trial % 4 == 0:
            x[rng.integers(0, n, 3)] = rng.choice([0.0, -0.0], 3)
        if trial % 7 == 0:
            x[:] = rng.choice([0.0, -0.0], n)  # the maximum is a zero of either sign
        scale = float(rng.choice([1.0, 10.0, 0.3, -2.0]))
        logits = x * scale
        want = np.exp(logits - logits.max())
        assert exp_shifted(x, scale).tobytes() == want.tobytes()
    for bad in (np.array([0.0, np.nan]), np.array([np.inf, 1.0]), np.array([1e308, -1.0])):
        with np.errstate(invalid="ignore", over="ignore"):
            got, want = exp_shifted(bad, 10.0), np.exp(bad * 10.0 - (bad * 10.0).max())
        np.testing.assert_array_equal(got, want)
    with pytest.raises(ValueError):
        exp_shifted(np.zeros(0))  # numpy's error: no maximum of nothing
