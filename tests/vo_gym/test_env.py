"""vo_gym.StereoVOEnv: registration, both env checkers, vector envs, spaces, validation, determinism,
no label leak, and that the action matters (oracle > uniform > adversarial).

Past 600 lines because every one of these is a property of the one environment class, each checked
on its own frames; split by topic, the files would share most of their fixtures."""

from __future__ import annotations

import contextlib
import dataclasses
import inspect
import io
import math
import pickle
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env, data_equivalence
from hypothesis import given, strategies as st
from stable_baselines3.common.env_checker import check_env as sb3_check_env
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

import vo_gym
import vo_gym.env as env_module
from stereovo.estimation import available_methods
from stereovo.simulation import Sequence, SimulationConfig
from tests.support.frames import frames_without_depth
from tests.support.fuzz import FUZZ, WEIRD_NUMBERS
from vo_gym import FEATURE_NAMES, N_FEATURES, StereoVOEnv
from vo_gym.features import usable_rows
from vo_gym.registration import ENV_IDS
from tests.support.processes import run_python

SHORT = dict(n_frames=4)  # short episodes: the checkers then also cross an episode end


def _rollout(env, seed, n_steps=None, action_seed=0):
    """Observations, rewards, truncations and infos of one episode under seeded random actions."""
    rng = np.random.default_rng(action_seed)
    obs, info = env.reset(seed=seed)
    record = [(obs, 0.0, False, info)]
    for _ in range(n_steps or env.unwrapped.sim_config.n_frames):
        action = rng.uniform(-3, 3, env.action_space.shape).astype(np.float32)
        obs, reward, terminated, truncated, info = env.step(action)
        assert terminated is False
        record.append((obs, reward, truncated, info))
    return record


def _same(a, b) -> bool:
    return data_equivalence(a, b, exact=True)


class _ShuffledLabelSequence(Sequence):
    """The same frames with every ground-truth label shuffled."""

    def frame(self, k):
        frame = super().frame(k)
        rng = np.random.default_rng(1000 + k)
        perm = rng.permutation(frame.n)
        truth = dataclasses.replace(
            frame.truth, inlier=frame.truth.inlier[perm], outlier_kind=frame.truth.outlier_kind[perm]
        )
        return dataclasses.replace(frame, truth=truth)


def _near(image, rgb, tol=0.06):
    """Pixels within ``tol`` (per channel, 0-1 scale) of the colour ``rgb``."""
    return int(np.count_nonzero(np.all(np.abs(image / 255.0 - np.asarray(rgb)) < tol, axis=-1)))


def _reddish(image):
    """Pixels of the estimated-inlier rings (tab:red, antialiased): strong red, weak green and blue."""
    im = image.astype(int)
    return int(np.count_nonzero((im[..., 0] > 150) & (im[..., 1] < 120) & (im[..., 2] < 120)))


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


def _readme_example() -> str:
    """The environment example of the README, read from the README so the two never drift apart."""
    text = (Path(__file__).resolve().parents[2] / "README.md").read_text()
    block = text.split("<!-- env-example -->", 1)[1]
    return block.split("```python", 1)[1].split("```", 1)[0]


ENV_KEYWORDS = ("sampling", "reward_mode", "max_correspondences", "action_bound", "logit_scale", "success_bonus",
                "hypothesis_cost", "failure_reward", "n_frames", "noise_sigma", "outlier_ratio", "score_auc",
                "z_min", "speed", "method", "budget", "batch_size", "estimator_noise_sigma", "refine", "confidence",
                "min_inliers", "local_refit", "bogus_keyword", "preset", "world", "outlier_mix")


def test_registered_ids():
    assert set(ENV_IDS) >= {"vo_gym/StereoVO-v0", "vo_gym/StereoVOProsac-v0", "vo_gym/StereoVOHard-v0"}
    for env_id in ENV_IDS:
        assert env_id in gym.registry
    vo_gym.register_envs()  # idempotent


def test_env_kind_tells_the_ids_apart_by_their_entry_point():
    from vo_gym.registration import ADAPTIVE_ENV_IDS, ENV_IDS as STEP_ENV_IDS, IMAGE_ENV_IDS
    from vo_gym.registration import IMAGES, IN_FRAME, OTHER, STEP, env_kind, step_ids

    assert step_ids() == tuple(sorted(STEP_ENV_IDS))  # what the one-shot trainers and the sweep's metric step
    assert {env_kind(i) for i in STEP_ENV_IDS} == {STEP}
    assert {env_kind(i) for i in ADAPTIVE_ENV_IDS} == {IN_FRAME} and {env_kind(i) for i in IMAGE_ENV_IDS} == {IMAGES}
    assert env_kind("StereoVO-v0") == OTHER  # the bare name: registered to an entry point that names the full id
    assert env_kind("CartPole-v1") == OTHER and env_kind("nosuch") is None


@pytest.mark.parametrize("env_id", sorted(ENV_IDS))
def test_gymnasium_check_env(env_id):
    env = gym.make(env_id, **SHORT)
    with warnings.catch_warnings():
        # The logit Box [-10, 10] is deliberately not [-1, 1] (see the env docstring).
        warnings.filterwarnings("ignore", message=".*symmetric and normalized")
        gym_check_env(env.unwrapped)
    env.close()


@pytest.mark.parametrize("env_id", sorted(ENV_IDS))
def test_sb3_check_env(env_id):
    env = gym.make(env_id, **SHORT)
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*symmetric and normalized")
        warnings.filterwarnings("ignore", message=".*unconventional shape")  # (N, F) needs a custom policy
        sb3_check_env(env.unwrapped, warn=True)
    env.close()


def test_make_without_import_by_module_prefix():
    code = (
        "import sys, gymnasium as gym\n"
        "assert 'vo_gym' not in sys.modules\n"
        "env = gym.make('vo_gym:vo_gym/StereoVO-v0', n_frames=2, n_correspondences=60)\n"
        "obs, _ = env.reset(seed=0)\n"
        "print(type(env.unwrapped).__name__, obs['features'].shape)\n"
    )
    assert run_python(code).strip() == f"StereoVOEnv (60, {N_FEATURES})"


def test_docstring_states_the_contract():
    doc = StereoVOEnv.__doc__
    for section in ("## Action Space", "## Observation Space", "## Rewards", "## Episode End", "## Arguments"):
        assert section in doc
    for name in inspect.signature(StereoVOEnv.__init__).parameters:
        if name not in ("self", "estimator_options"):
            assert f"``{name}``" in doc, f"argument {name} is not documented"


def test_simulator_defaults_match_the_simulator():
    params = inspect.signature(StereoVOEnv.__init__).parameters
    for field in dataclasses.fields(SimulationConfig):
        if field.name != "camera":
            assert params[field.name].default == field.default, field.name


def test_spaces_and_episode_end():
    env = StereoVOEnv(n_frames=3, n_correspondences=120)
    assert env.observation_space["features"].shape == (120, N_FEATURES)
    assert env.observation_space["features"].dtype == np.float32
    assert env.action_space.shape == (120,)
    record = _rollout(env, seed=3)
    assert [r[2] for r in record] == [False, False, False, True]
    for obs, reward, _, info in record:
        assert obs in env.observation_space
        assert -1.0 <= reward <= 1.0
    final = record[-1][3]["trajectory"]
    assert final["n_poses"] == 4 and 0.0 <= final["success_rate"] <= 1.0
    assert all(not (isinstance(v, float) and math.isnan(v)) for v in final.values())
    assert "trajectory" not in record[-2][3]
    for key in ("rot_err_deg", "trans_err_m", "success", "precision", "recall", "n_hypotheses", "n_point_checks"):
        assert key in record[1][3]
    assert not any("time" in key for _, _, _, info in record for key in info)
    with pytest.raises(RuntimeError, match="reset"):
        env.step(env.action_space.sample())
    assert env.estimated_poses.shape == env.true_poses.shape == (4, 4, 4)


def test_the_episodes_success_rate_is_the_mean_of_its_steps_success():
    # Contamination 0.6 under a budget of 4 hypotheses: some frames of this episode succeed and some do not.
    env = StereoVOEnv(n_frames=4, n_correspondences=80, outlier_ratio=0.6, budget=4)
    record = _rollout(env, seed=1)
    successes = [info["success"] for _, _, _, info in record[1:]]
    assert len(successes) == 4 and any(successes) and not all(successes)
    assert record[-1][3]["trajectory"]["success_rate"] == sum(successes) / 4


@pytest.mark.parametrize("env_id", ["vo_gym/StereoVO-v0", "vo_gym/StereoVOProsac-v0", "vo_gym/StereoVOAdaptive-v0"])
def test_float32_actions_step_as_their_float64_cast(env_id):
    records = []
    for dtype in (np.float32, np.float64):
        env = gym.make(env_id, n_frames=3, max_correspondences=520)
        env.reset(seed=4)
        rng = np.random.default_rng(4)
        steps = []
        for _ in range(10):
            action = (rng.standard_normal(env.action_space.shape) * 8).astype(np.float32)  # some past the bound
            action[500:-1] = np.nan  # padding: ignored
            obs, reward, _, truncated, info = env.step(action.astype(dtype))
            steps.append((obs, reward, info))
            if truncated:
                env.reset()
        records.append(steps)
    assert _same(records[0], records[1])


def test_settings_reach_the_simulator_and_messages_name_the_environment():
    env = StereoVOEnv(n_correspondences=50, outliers="hostile", noise_dof=4.0)
    assert env.sim_config.outliers == "hostile" and env.sim_config.noise_dof == 4.0
    for kwargs, error, match in (
        ({"max_correspondences": 5}, ValueError, r"^StereoVOEnv: max_correspondences=5 is smaller"),
        ({"outliers": "nope"}, ValueError, r"^StereoVOEnv: invalid simulator setting"),
        ({"budget": -3}, ValueError, r"^StereoVOEnv: budget must be"),
        ({"msac_threshold": 1.0}, TypeError, r"^StereoVOEnv got unexpected keyword argument"),
    ):
        with pytest.raises(error, match=match):
            StereoVOEnv(**kwargs)
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"^StereoVOEnv: the action must have shape \(50,\), one value per "
                                         r"correspondence slot, got \(1, 2\)$"):
        env.step([[1.0, 2.0]])
    _, reward, *_ = env.step(list(np.zeros(50)))  # a list of floats takes the checked path
    assert np.isfinite(reward)


def test_padding_and_action_validation():
    env = StereoVOEnv(n_frames=2, n_correspondences=50, max_correspondences=64)
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros(64, np.float32))
    obs, _ = env.reset(seed=0)
    assert obs["features"].shape == (64, N_FEATURES)
    assert obs["mask"].sum() == 50 and np.all(obs["mask"][50:] == 0) and np.all(obs["features"][50:] == 0)
    for bad, match in ((np.zeros(50), "shape"), (np.zeros((64, 1)), "shape"), ("logits", "numeric")):
        with pytest.raises(ValueError, match=match):
            env.step(bad)
    for dtype in (np.float64, np.float32):  # float32 actions are clipped without the cast
        nan = np.zeros(64, dtype=dtype)
        nan[7] = np.nan
        with pytest.raises(ValueError, match="NaN or inf"):
            env.step(nan)
    masked = np.zeros(64)
    masked[50:] = -np.inf  # masked logits in padded slots are ignored
    env.step(masked)
    env.step(np.full(64, 1e6))  # out-of-Box values are clipped
    assert env.frame_index == 3


@pytest.mark.filterwarnings("ignore:.*render_mode")
@pytest.mark.parametrize(
    "kwargs, error, match",
    [
        (dict(outlier_ratio=1.5), ValueError, "outlier_ratio"),
        (dict(n_correspondences=2), ValueError, "n_correspondences"),
        (dict(preset="boat"), ValueError, "preset"),
        (dict(max_correspondences=100), ValueError, "max_correspondences"),
        (dict(sampling="lottery"), ValueError, "sampling"),
        (dict(reward_mode="vibes"), ValueError, "reward_mode"),
        (dict(budget=0), ValueError, "budget"),
        (dict(budget=2.5), ValueError, "budget"),
        (dict(method="magic"), ValueError, "unknown method"),
        (dict(confidence=1.5), ValueError, "confidence"),
        (dict(threshold_px=-1.0), ValueError, "threshold_px"),
        (dict(action_bound=0.0), ValueError, "action_bound"),
        (dict(success_bonus=2.0), ValueError, "success_bonus"),
        (dict(failure_reward=-3.0), ValueError, "failure_reward"),
        (dict(render_mode="ansi"), ValueError, "render_mode"),
        (dict(noise_sigma=0.0), ValueError, "estimator_noise_sigma"),
        (dict(bogus=1), TypeError, "bogus"),
    ],
)
def test_invalid_settings_are_rejected_by_make(kwargs, error, match):
    with pytest.raises(error, match=match):
        gym.make("vo_gym/StereoVO-v0", n_correspondences=kwargs.pop("n_correspondences", 200), **kwargs)


@pytest.mark.skipif("mlesac" not in available_methods() or "prosac" not in available_methods(),
                    reason="the classical methods are not registered")
def test_method_options_and_sampling_are_checked_when_made():
    with pytest.raises(ValueError, match="mlesac_em_iterations"):
        StereoVOEnv(n_correspondences=100, method="mlesac", mlesac_em_iterations=0)
    with pytest.raises(TypeError, match="sprt_t_m"):
        StereoVOEnv(n_correspondences=100, method="mlesac", sprt_t_m=10)
    with pytest.raises(ValueError, match="sampling='guided'"):  # PROSAC needs an order, not priors
        StereoVOEnv(n_correspondences=100, method="prosac", sampling="guided")
    StereoVOEnv(n_correspondences=100, method="prosac", sampling="prosac")


def test_estimator_settings_pass_through():
    env = gym.make("vo_gym/StereoVO-v0", n_frames=2, n_correspondences=100, budget=8, batch_size=4,
                   method="ransac", refine=False, threshold_px=2.0)
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.zeros(100, np.float32))
    assert info["n_hypotheses"] == 8
    options = env.unwrapped.estimator_options
    assert (options.budget, options.batch_size, options.refine, options.threshold_px) == (8, 4, False, 2.0)
    noise_free = StereoVOEnv(n_frames=1, n_correspondences=80, noise_sigma=0.0, estimator_noise_sigma=0.3)
    noise_free.reset(seed=0)
    assert noise_free.step(np.zeros(80))[4]["success"]


@pytest.mark.parametrize("sampling", ["guided", "prosac"])
def test_same_seed_same_actions_identical_episodes(sampling):
    kwargs = dict(sampling=sampling, n_frames=5, n_correspondences=200, outlier_ratio=(0.4, 0.7))
    a = _rollout(StereoVOEnv(**kwargs), seed=11)
    b = _rollout(gym.make("vo_gym/StereoVO-v0", **kwargs), seed=11)
    assert len(a) == len(b)
    for (obs_a, r_a, tr_a, info_a), (obs_b, r_b, tr_b, info_b) in zip(a, b):
        assert _same(obs_a, obs_b) and r_a == r_b and tr_a == tr_b and _same(info_a, info_b)
    c = _rollout(StereoVOEnv(**kwargs), seed=12)
    assert not _same(a[1][0], c[1][0])


def test_reset_seed_reproduces_on_the_same_env_and_after_pickling():
    env = StereoVOEnv(n_frames=3, n_correspondences=150, outlier_ratio=0.6)
    first = _rollout(env, seed=5)
    again = _rollout(env, seed=5)
    assert all(_same(x[0], y[0]) and x[1] == y[1] and _same(x[3], y[3]) for x, y in zip(first, again))
    # Mid-episode pickling (AsyncVectorEnv / SubprocVecEnv ship envs between processes) keeps the stream.
    env.reset(seed=5)
    env.step(np.zeros(150))
    clone = pickle.loads(pickle.dumps(env))
    action = np.linspace(-1, 1, 150)
    out_a, out_b = env.step(action), clone.step(action)
    assert _same(out_a[0], out_b[0]) and out_a[1] == out_b[1] and _same(out_a[4], out_b[4])


@pytest.mark.parametrize("reward_mode", ["supervised", "msac", "inliers"])
def test_shuffled_labels_give_identical_observations(monkeypatch, reward_mode):
    kwargs = dict(n_frames=4, n_correspondences=200, outlier_ratio=0.6, reward_mode=reward_mode)
    plain = _rollout(StereoVOEnv(**kwargs), seed=21)
    monkeypatch.setattr(env_module, "Sequence", _ShuffledLabelSequence)
    shuffled = _rollout(StereoVOEnv(**kwargs), seed=21)
    for (obs_a, r_a, _, info_a), (obs_b, r_b, _, info_b) in zip(plain, shuffled):
        assert _same(obs_a, obs_b)
        if reward_mode != "supervised":  # self-supervised rewards need no labels either
            assert r_a == r_b
    # The labels did change: precision against them collapses.
    assert np.mean([x[3]["precision"] for x in shuffled[1:]]) < np.mean([x[3]["precision"] for x in plain[1:]]) - 0.2


def test_reward_modes_are_bounded_and_ordered():
    for mode in ("supervised", "inliers", "msac"):
        env = StereoVOEnv(n_frames=2, n_correspondences=200, outlier_ratio=0.3, reward_mode=mode, hypothesis_cost=0.0)
        env.reset(seed=0)
        inlier = env.current_frame.truth.inlier
        good = env.step(np.where(inlier, 10.0, -10.0))[1]
        assert -1.0 <= good <= 1.0
        if mode == "inliers":
            assert abs(good - np.mean(inlier)) < 0.1  # the inlier fraction of a correct model
        if mode == "supervised":
            assert good > 0.5
    fail = StereoVOEnv(n_frames=1, n_correspondences=100, min_inliers=99, failure_reward=-0.7)
    fail.reset(seed=0)
    _, reward, _, _, info = fail.step(np.zeros(100))
    assert info["status"] != "ok" and info["fallback"] and reward == -0.7


def test_render_rgb_array_draws_the_weights_and_the_inliers():
    teal, purple = (0.128, 0.567, 0.551), (0.267, 0.005, 0.329)  # viridis at 1 x uniform (mid-scale) and at 1e-2

    def rendered(action, before=False):
        env = gym.make("vo_gym/StereoVO-v0", n_frames=2, n_correspondences=100, render_mode="rgb_array")
        env.reset(seed=0)
        first = env.render() if before else None
        env.step(action)
        return first, env.render()

    first, uniform = rendered(np.zeros(100, np.float32), before=True)
    # Half the matches at +10, half at -10: weights 2 and ~2e-20 x uniform (drawn at the 1e-2 end of the scale).
    _, split = rendered(np.where(np.arange(100) < 50, 10.0, -10.0).astype(np.float32))
    assert uniform.dtype == np.uint8 and uniform.shape == (420, 1200, 3) and first.shape == uniform.shape
    # Before any step no estimate exists: nothing ringed; after one, the estimate's inliers are ringed in red.
    assert _reddish(first) == 0 and _reddish(uniform) > 100
    # The matches are coloured by their weight: mid-scale teal under uniform weights; half of them move to
    # the purple end when their weight collapses (the colour bar draws both colours in both images).
    assert _near(uniform, teal) > _near(split, teal) + 500
    assert _near(split, purple) > _near(uniform, purple) + 200
    with pytest.warns(UserWarning, match="render_mode"):
        assert StereoVOEnv(n_frames=1).render() is None  # no render_mode: nothing to draw


def test_feature_layout_is_exposed():
    env = StereoVOEnv(n_frames=1, n_correspondences=50)
    assert env.feature_names == FEATURE_NAMES == vo_gym.FEATURE_NAMES
    assert env.feature_layout_version == vo_gym.FEATURE_LAYOUT_VERSION


def test_gymnasium_sync_and_async_agree():
    sync, sync_ends = _run_gym_vector("sync")
    asyn, async_ends = _run_gym_vector("async")
    assert [e.tolist() for e in sync_ends] == [[False, False], [False, False], [True, True], [False, False]]
    assert all(np.array_equal(a, b) for a, b in zip(sync_ends, async_ends))
    assert data_equivalence(sync, asyn, exact=True)
    final_info = sync[3][2]
    assert "trajectory" in final_info and final_info["_trajectory"].all()


@pytest.mark.parametrize("vec_cls", [DummyVecEnv, SubprocVecEnv])
def test_sb3_vec_envs_step_exactly_like_the_plain_env(vec_cls):
    # Workers are forked here to keep the test fast (forkserver/spawn workers import torch afresh, ~10 s).
    # Under forkserver/spawn a worker has not imported vo_gym: name the module in the id,
    # "vo_gym:vo_gym/StereoVOProsac-v0" (test_make_without_import_by_module_prefix checks that form in a fresh interpreter).
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


@pytest.mark.parametrize("sampling", ["guided", "prosac"])
def test_oracle_beats_uniform_beats_adversarial(sampling):
    oracle, uniform, adversarial = (_evaluate(agent, sampling) for agent in (_oracle, _uniform, _adversarial))
    # (mean reward, success rate) of each agent on the same trajectories
    assert oracle[1] >= 0.95 and oracle[0] > 0.8
    assert oracle[0] > uniform[0] + 0.3 and oracle[1] > uniform[1] + 0.3
    assert uniform[0] > adversarial[0] + 0.1 and uniform[1] >= adversarial[1]
    assert adversarial[1] <= 0.1


def test_readme_example():
    out, namespace = io.StringIO(), {}
    with contextlib.redirect_stdout(out):
        exec(compile(_readme_example(), "README example", "exec"), namespace)
    assert namespace["truncated"]  # the loop ran exactly one episode
    text = out.getvalue().strip()
    assert text.startswith("success rate ")
    assert float(text.split()[-1]) >= 0.6  # the heuristic (0.9) clearly beats uniform sampling (0.38 on these frames)


@pytest.mark.parametrize("name,value", [
    ("batch_size", 1.5), ("refine", "no"), ("local_refit", "no"), ("polish_iterations", 1.5),
    ("refine_iterations", 2.5), ("min_inliers", 3.5), ("max_iterations", math.inf), ("budget", math.nan),
    ("confidence", "0.9"), ("budget", True), ("estimator_noise_sigma", 1e300), ("action_bound", math.inf),
    ("success_bonus", "0.5"), ("sampling", 1), ("noise_sigma", 1e300),
])
def test_make_keywords_follow_the_contract(name, value):
    with pytest.raises(ValueError, match=name):
        gym.make("vo_gym/StereoVO-v0", n_correspondences=60, **{name: value})


def test_env_learns_validity_without_running_the_method(monkeypatch):
    """No probe frame: making an env with bad method options fails before any estimate is run."""
    import stereovo.estimation.api as methods

    def boom(*args, **kwargs):
        raise AssertionError("the environment ran the estimator while being made")

    monkeypatch.setattr(methods, "_estimate", boom)
    with pytest.raises(ValueError, match="prosac_beta"):
        StereoVOEnv(n_correspondences=60, method="usac", prosac_beta=5.0)
    with pytest.raises(ValueError, match="sampling='guided'"):
        StereoVOEnv(n_correspondences=60, method="prosac")
    StereoVOEnv(n_correspondences=60, method="prosac", sampling="prosac", prosac_beta=0.1)


def test_environment_steps_through_frames_with_unusable_rows():
    import gymnasium

    import vo_gym  # noqa: F401

    env = gymnasium.make("vo_gym/StereoVO-v0", n_frames=3, n_correspondences=100).unwrapped
    with pytest.MonkeyPatch.context() as patch:
        frames_without_depth(patch, [0, 1, 2, 3])  # the frame of the first step loses the depth of four rows
        obs, _ = env.reset(seed=0)
    assert np.all(np.isfinite(obs["features"]))
    np.testing.assert_array_equal(obs["mask"][:4], 0)
    assert obs["mask"][4:].all()
    action = np.zeros(env.action_space.shape, dtype=np.float32)
    action[:4] = -np.inf  # masked logits on the unusable rows are accepted
    obs, reward, terminated, truncated, info = env.step(action)
    assert np.isfinite(reward) and info["status"] == "ok"


def test_image_frames_read_the_action_slots_of_their_own_matches_only():
    # An image frame has as many matches as the front end found, fewer than the observation's rows (here a
    # replayed source of 40-match frames in 64 rows): the slots past the frame's matches are padding, whatever
    # they hold (NaN included), and a NaN in one of the frame's own slots is refused by its slot number.
    from vo_gym.images_env import ReplayedFrames, StereoVOImagesEnv

    sequence = Sequence(SimulationConfig(n_frames=3, n_correspondences=40), seed=5)
    frames = list(sequence)
    source = ReplayedFrames(frames, frames[0].camera, sequence.true_poses, frames[0].noise_sigma)
    env = StereoVOImagesEnv(source=source, n_frames=2, max_correspondences=64)
    logits = np.linspace(-2.0, 2.0, 40)
    steps = []
    for padding in (0.0, 10.0, np.nan):
        obs, _ = env.reset(seed=0)
        assert env.current_frame.n == 40 and obs["mask"].tolist() == [1] * 40 + [0] * 24
        _, reward, _, _, info = env.step(np.concatenate([logits, np.full(24, padding)]))
        steps.append((reward, info))
    assert math.isfinite(steps[0][0]) and _same(steps[0], steps[1]) and _same(steps[0], steps[2])
    env.reset(seed=0)
    own = np.zeros(64)
    own[39] = np.nan
    with pytest.raises(ValueError, match=r"^StereoVOImagesEnv: the action has NaN or inf in 1 valid slot\(s\) "
                                         r"\(first: slot 39\)$"):
        env.step(own)


def test_min_disparity_sigmas_decides_which_rows_of_the_observation_have_depth():
    # A row has a depth when its disparity at k-1 and at k exceeds min_disparity_sigmas standard deviations of a
    # disparity, sqrt(2) sigma: at 20 (14.1 px for sigma 0.5 px) the far rows of this frame lose it, in the mask
    # and in the features' depth flag; the default, 2 (1.4 px), keeps every row of the same frame.
    env = StereoVOEnv(n_frames=2, n_correspondences=100, min_disparity_sigmas=20.0)
    obs, _ = env.reset(seed=3)
    frame = env.current_frame
    threshold = 20.0 * math.sqrt(2.0) * env.estimator_noise_sigma
    resolvable = (frame.prev[:, 0] - frame.prev[:, 2] > threshold) & (frame.curr[:, 0] - frame.curr[:, 2] > threshold)
    assert env.estimator_noise_sigma == 0.5 and 10 < resolvable.sum() < 90
    assert obs["mask"].dtype == np.int8
    np.testing.assert_array_equal(obs["mask"], resolvable.astype(np.int8))
    np.testing.assert_array_equal(usable_rows(obs["features"]), resolvable)
    default, _ = StereoVOEnv(n_frames=2, n_correspondences=100).reset(seed=3)
    assert default["mask"].all() and usable_rows(default["features"]).all()
    _, reward, *_ = env.step(np.zeros(100, np.float32))
    assert math.isfinite(reward)


def test_rendered_prosac_weights_run_from_one_for_the_best_to_zero_for_the_worst():
    # A rendering colours PROSAC's matches by rank: the first of the order weighs 1, the last 0, evenly between;
    # with two matches the two ends, with one match 1 (no division by zero). Guided priors are scaled to mean 1.
    weights = env_module._display_weights
    assert weights(1, None, np.array([0])).tolist() == [1.0]
    assert weights(2, None, np.array([1, 0])).tolist() == [0.0, 1.0]
    assert weights(5, None, np.array([3, 0, 4, 1, 2])).tolist() == [0.75, 0.25, 0.0, 1.0, 0.5]
    assert weights(4, np.array([1.0, 3.0, 0.0, 4.0]), None).tolist() == [0.5, 1.5, 0.0, 2.0]


# Two valid values for each keyword of ENV_KEYWORDS (bogus_keyword has none, and confidence none under the fuzz
# test's fixed budget, which refuses it as ignored); n_frames and budget replace the fuzz test's base settings.
ENV_VALID = {
    "sampling": ("guided", "prosac"), "reward_mode": ("supervised", "msac"), "max_correspondences": (None, 64),
    "action_bound": (10.0, 5), "logit_scale": (1.0, 0.5), "success_bonus": (0.5, 0.0), "hypothesis_cost": (0.001, 0),
    "failure_reward": (-1.0, -0.5), "n_frames": (2, 3), "noise_sigma": (0.5, 1.0), "outlier_ratio": (0.5, (0.2, 0.6)),
    "score_auc": (0.75, 0.9), "z_min": (3.0, 5.0), "speed": (None, 8.0), "method": ("msac", "ransac"),
    "budget": (4, 8), "batch_size": (None, 2), "estimator_noise_sigma": (None, 0.7), "refine": (False, True),
    "min_inliers": (6, 8), "local_refit": (False, True), "preset": ("car", "free"),
    "world": (None, "open"), "outlier_mix": (None, (0.8, 0.2, 0.0)),
}
VALID_ACTIONS = ("zeros", "random", "inf-pad", "huge")


def test_env_make_reset_step_fuzz():
    # Most examples give their keyword a valid value (ENV_VALID) and a valid action, and play the whole episode
    # to its truncation; the rest give a WEIRD_NUMBERS (or a name) value, refused by gym.make naming the keyword,
    # or an invalid action, refused by the first step naming the action. A valid value is never refused, a valid
    # action never, an invalid one always. The outcomes are counted.
    outcomes = []

    @FUZZ
    @given(keyword=st.sampled_from(ENV_KEYWORDS), valid=st.sampled_from([True, True, True, False]),
           pick=st.integers(0, 1), weird=WEIRD_NUMBERS | st.sampled_from(["msac", "prosac", "guided", "car"]),
           seed=st.integers(0, 2**31),
           action=st.sampled_from([*VALID_ACTIONS, *VALID_ACTIONS, "nan", "shape", "complex", "text"]))
    def run(keyword, valid, pick, weird, seed, action):
        valid = valid and keyword in ENV_VALID
        settings = {"n_frames": 2, "n_correspondences": 40, "budget": 4,
                    keyword: ENV_VALID[keyword][pick] if valid else weird}
        try:
            env = gym.make("vo_gym/StereoVO-v0", **settings)
        except (ValueError, TypeError) as err:
            assert keyword in str(err), repr(err)
            assert not valid, repr(err)
            outcomes.append("make refused")
            return
        obs, _ = env.reset(seed=seed)
        space = env.observation_space
        assert space.contains(obs)
        m = env.action_space.shape[0]
        assert m == max(40, settings.get("max_correspondences") or 0)
        rng = np.random.default_rng(seed)
        candidate = {
            "zeros": np.zeros(m, np.float32), "random": rng.normal(size=m).astype(np.float32),
            "nan": np.full(m, np.nan), "inf-pad": np.concatenate([np.zeros(40), np.full(m - 40, -np.inf)]),
            "shape": np.zeros(m + 1), "complex": np.zeros(m, complex), "huge": np.full(m, 1e300), "text": "logits",
        }[action]
        n_frames = env.unwrapped.sim_config.n_frames
        assert n_frames == settings["n_frames"]
        for step in range(n_frames):
            try:
                obs, reward, terminated, truncated, info = env.step(candidate)
            except ValueError as err:
                assert "action" in str(err), repr(err)
                assert step == 0 and action not in VALID_ACTIONS, repr(err)
                outcomes.append("action refused")
                return
            assert action in VALID_ACTIONS
            assert space.contains(obs) and -1.0 <= reward <= 1.0 and math.isfinite(reward) and not terminated
            assert truncated == (step == n_frames - 1)
            assert info["status"] == "ok" or info["status"].startswith("failed")
        assert truncated and "trajectory" in info
        outcomes.append("episode")

    run()
    tally = {outcome: outcomes.count(outcome) for outcome in set(outcomes)}
    assert len(outcomes) == 30
    assert tally.get("episode", 0) >= 10 and tally.get("make refused", 0) >= 3, tally
    assert tally.get("action refused", 0) >= 3, tally
