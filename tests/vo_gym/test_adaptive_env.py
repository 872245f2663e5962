"""The in-frame adaptive environment (vo_gym.adaptive_env): spaces, checkers, determinism, frame ends,
rewards (a frame's sum to the zero-cost reward less its hypotheses' cost, as documented), selection, the
agent's prior sampler, render() without a render mode (as the step environment), pickling."""

from __future__ import annotations

import dataclasses
import pickle

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import data_equivalence

from stereovo.estimation import StereoProblem
from stereovo.estimation.loop import LoopState
from stereovo.metrics import FrameMetrics
from vo_gym.adaptive_env import (
    GLOBAL_FEATURE_NAMES,
    LOOP_FEATURE_NAMES,
    AgentPriorSampler,
    StereoVOAdaptiveEnv,
)
from vo_gym.env import StereoVOEnv
from vo_gym.features import N_FEATURES
from vo_gym.registration import HARD_SETTINGS
from vo_gym.rewards import inlier_reward, supervised_reward


def small(**kwargs) -> StereoVOAdaptiveEnv:
    return StereoVOAdaptiveEnv(**{"n_frames": 3, "n_correspondences": 80, "outlier_ratio": 0.5, **kwargs})


def act(env, stop: bool, logits: np.ndarray | None = None) -> np.ndarray:
    a = np.zeros(env.action_space.shape, dtype=np.float32)
    if logits is not None:
        a[: len(logits)] = logits
    a[-1] = 1.0 if stop else -1.0
    return a


def rollout(env, seed: int, stop_at: int):
    obs, _ = env.reset(seed=seed)
    out = [obs]
    while True:
        obs, reward, terminated, truncated, info = env.step(act(env, env.frame_hypotheses >= stop_at))
        out.append((obs, reward, info))
        if truncated:
            return out


def test_spaces_and_both_checkers_pass():
    from gymnasium.utils.env_checker import check_env
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = small(max_correspondences=96)
    assert env.observation_space["features"].shape == (96, N_FEATURES + len(LOOP_FEATURE_NAMES))
    assert env.observation_space["globals"].shape == (len(GLOBAL_FEATURE_NAMES),)
    assert env.action_space.shape == (97,)
    check_env(env, skip_render_check=True)
    sb3_check_env(small(), warn=False)


def test_registered_ids():
    env = gym.make("vo_gym/StereoVOAdaptiveHard-v0", n_frames=2, n_correspondences=60)
    assert env.unwrapped.sim_config.outlier_mix == HARD_SETTINGS["outlier_mix"]
    assert env.unwrapped.sim_config.score_auc == HARD_SETTINGS["score_auc"]
    assert isinstance(gym.make("vo_gym/StereoVOAdaptive-v0", n_frames=2).unwrapped, StereoVOAdaptiveEnv)


def test_same_seed_same_episode():
    a, b = rollout(small(), 7, 8), rollout(small(), 7, 8)
    assert len(a) == len(b)
    for x, y in zip(a[1:], b[1:]):
        np.testing.assert_array_equal(x[0]["features"], y[0]["features"])
        np.testing.assert_array_equal(x[0]["globals"], y[0]["globals"])
        assert x[1] == y[1]
        assert x[2].keys() == y[2].keys()
        np.testing.assert_array_equal(x[2]["batch_samples"], y[2]["batch_samples"])
    c = rollout(small(), 8, 8)
    assert any(not np.array_equal(x[0]["features"], y[0]["features"]) for x, y in zip(a[1:], c[1:]))


def test_stop_before_any_hypothesis_draws_a_batch_then_stop_and_cap_end_the_frame():
    env = small(batch_size=3, max_hypotheses=7, hypothesis_cost=0.01)
    obs, _ = env.reset(seed=1)
    assert obs["globals"][0] == 0 and not obs["features"][:, N_FEATURES:].any()
    _, reward, _, _, info = env.step(act(env, True))
    assert not info["frame_done"] and info["frame_hypotheses"] == 3 and info["batch_count"] == 3
    assert reward == pytest.approx(-0.03)
    obs, reward, _, _, info = env.step(act(env, True))  # the agent stops: no new hypotheses
    assert info["frame_done"] and info["stopped"] and info["n_hypotheses"] == 3 and info["batch_count"] == 0
    metrics = FrameMetrics(**{k: info[k] for k in FrameMetrics.__dataclass_fields__ if k != "time_s"}, time_s=0.0)
    assert reward == pytest.approx(supervised_reward(metrics, 0.5, 0.0, -1.0))
    assert info["frame"] == 1 and env.frame_hypotheses == 0 and obs["globals"][5] == float(not info["fallback"])
    for expected in (3, 6):  # the cap: 3 + 3 + 1
        _, _, _, _, info = env.step(act(env, False))
        assert info["frame_hypotheses"] == expected and not info["frame_done"]
    _, _, _, _, info = env.step(act(env, False))
    assert info["frame_done"] and not info["stopped"] and info["n_hypotheses"] == 7


def test_loop_features_follow_the_search():
    env = small(batch_size=4)
    env.reset(seed=2)
    obs, _, _, _, info = env.step(act(env, False))
    n = env.current_frame.n
    votes = info["batch_inliers"][: info["batch_count"], :n].sum(axis=0)
    np.testing.assert_allclose(obs["features"][:n, N_FEATURES + 1], votes / 4, rtol=1e-6)
    np.testing.assert_allclose(obs["features"][:n, N_FEATURES + 2], np.log1p(votes), rtol=1e-6)
    best = obs["features"][:n, N_FEATURES + 3].astype(bool)
    assert best.sum() == info["batch_inliers"].sum(axis=1).max()
    assert obs["globals"][1] == pytest.approx(best.sum() / n)


def test_selection_weights_consensus_by_the_agents_beliefs():
    sampler = AgentPriorSampler(6)
    big = np.array([[1, 1, 1, 1, 0, 0]], dtype=bool)  # a larger consensus (e.g. a moving object)
    small_ = np.array([[0, 0, 0, 0, 1, 1]], dtype=bool)
    for mask in (big, small_):  # two scored hypotheses, reported through the loop's feedback hook
        state = LoopState(1, 0.0, samples=np.zeros((1, 3), dtype=np.int64))
        sampler.on_hypotheses(np.eye(3)[None], np.zeros((1, 3)), mask, None, state)
    np.testing.assert_array_equal(sampler.scored_masks, np.concatenate([big, small_]))
    assert sampler.select(np.full(6, 1 / 6)) == 0  # uniform beliefs: the larger consensus
    assert sampler.select(np.array([0.01, 0.01, 0.01, 0.01, 0.48, 0.48])) == 1


def test_bad_actions_and_arguments_raise_naming_them():
    env = small()
    env.reset(seed=0)
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros(5))
    bad = act(env, False)
    bad[0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        env.step(bad)
    for dtype in (np.float32, np.float64):  # float actions are read without real_array's cast
        for slot in (0, -1):
            bad = act(env, False).astype(dtype)
            bad[slot] = np.inf
            with pytest.raises(ValueError, match="NaN or inf"):
                env.step(bad)
    for dtype in (np.float32, np.float64, np.int64):
        with pytest.raises(ValueError, match="shape"):
            env.step(np.zeros(5, dtype=dtype))
    for kwargs, name in (({"batch_size": 0}, "batch_size"), ({"hypothesis_cost": -1}, "hypothesis_cost"),
                         ({"reward_mode": "x"}, "reward_mode"), ({"max_correspondences": 10}, "max_correspondences")):
        with pytest.raises(ValueError, match=name):
            small(**kwargs)
    with pytest.raises(RuntimeError, match="reset"):
        small().step(np.zeros(81))


@pytest.mark.parametrize("env_id", ["vo_gym/StereoVOAdaptive-v0", "vo_gym/StereoVOAdaptiveHard-v0"])
def test_gymnasium_tools_pass_render_mode_none_and_a_mode_without_a_renderer_is_refused(env_id):
    env = gym.make(env_id, render_mode=None, n_frames=1, n_correspondences=60)
    assert env.unwrapped.render_mode is None and env.metadata["render_modes"] == []
    env.reset(seed=0)
    with pytest.raises(ValueError) as err:
        small(render_mode="rgb_array")
    assert str(err.value) == ("StereoVOAdaptiveEnv: render_mode must be None (the environment has no renderer: "
                              "metadata['render_modes'] is empty), got 'rgb_array'")


@pytest.mark.parametrize("name, value, why", [
    ("budget", 8, "the agent decides when to stop a frame's search, under the cap max_hypotheses"),
    ("confidence", 0.1, "the agent decides when to stop a frame's search; no confidence bound runs"),
    ("max_iterations", 8, "the per-frame cap is the environment's max_hypotheses"),
    ("first_batch_size", 1, "every step draws the environment's batch_size hypotheses"),
    ("fail_at_cap", False, "a frame that reaches max_hypotheses ends on its best-supported hypothesis"),
])
def test_the_stopping_rules_options_are_refused_not_ignored(name, value, why):
    # the agent's stop under max_hypotheses replaces the search's stopping rule, which reads these
    with pytest.raises(TypeError) as err:
        small(**{name: value})
    assert str(err.value).startswith(f"StereoVOAdaptiveEnv: {name}={value!r} does not apply: {why}")
    with pytest.raises(TypeError) as err:  # nor are they listed as options of the method
        small(zzz=1)
    assert f"'{name}'" not in str(err.value)


@pytest.mark.parametrize("method", ["guided-mlesac", "prosac", "inlier-detection"])
def test_a_method_that_cannot_judge_the_search_is_refused_at_construction(method):
    with pytest.raises(ValueError, match=f"method '{method}' cannot judge the in-frame search"):
        small(method=method)


def test_mlesac_judges_frames_with_rows_without_depth():
    """The search judges the whole frame, rows without depth included: MLESAC's densities stay
    finite there (such a row is an outlier under every motion) and the episode runs."""
    env = small(method="mlesac", n_frames=4, n_correspondences=120, outliers="hostile")
    env.reset(seed=1)
    all_rows_have_depth = []  # of the frame judged at each step
    while True:
        frame, options = env.current_frame, env.estimator_options
        all_rows_have_depth.append(StereoProblem.build(frame.prev, frame.curr, frame.camera, options.noise_sigma,
                                                       options.min_disparity_sigmas).usable_mask.all())
        obs, reward, terminated, truncated, info = env.step(act(env, env.frame_hypotheses >= 32))
        assert np.isfinite(reward) and all(np.isfinite(value).all() for value in obs.values())
        if truncated:
            break
    assert not any(all_rows_have_depth)


def test_agent_sampler_keeps_every_scored_mask_in_order_across_its_buffer_growth():
    sampler = AgentPriorSampler(5)
    rng = np.random.default_rng(1)
    masks = [rng.random((k, 5)) < 0.5 for k in (40, 30, 7)]  # 77 rows: the 64-row buffer doubles
    for m in masks:
        sampler.on_hypotheses(None, None, m, None, LoopState(0, 0.0, samples=np.zeros((m.shape[0], 3), dtype=np.int64)))
    np.testing.assert_array_equal(sampler.scored_masks, np.concatenate(masks))
    w = rng.random(5)
    assert sampler.select(w) == int(np.argmax(np.concatenate(masks) @ w)) and sampler.n_scored() == 77


def test_batch_infos_have_a_fixed_shape_padded_after_the_count():
    env = small(batch_size=3, max_hypotheses=7, max_correspondences=96)
    env.reset(seed=4)
    n = env.current_frame.n
    counts = []
    for stop in (False, True, False, False, False):  # a batch, a stop, then 3 + 3 + 1 up to the cap
        before = env.scored_inliers.shape[0]
        _, _, _, _, info = env.step(act(env, stop))
        count = info["batch_count"]
        counts.append(count)
        assert info["batch_samples"].shape == (3, 3) and info["batch_samples"].dtype == np.int64
        assert info["batch_inliers"].shape == (3, 96) and info["batch_inliers"].dtype == bool
        assert (info["batch_samples"][count:] == -1).all() and not info["batch_inliers"][count:].any()
        assert not info["batch_inliers"][:, n:].any() and (info["batch_samples"][:count] >= 0).all()
        if count and not info["frame_done"]:  # the rows are the frame's last scored masks
            np.testing.assert_array_equal(info["batch_inliers"][:count, :n], env.scored_inliers[before:before + count])
    assert counts == [3, 0, 3, 3, 1]


def test_gymnasium_vector_env_steps_the_adaptive_env():
    from gymnasium.utils.performance import benchmark_vector_step

    envs = gym.make_vec("vo_gym/StereoVOAdaptive-v0", num_envs=2, vectorization_mode="sync",
                        n_frames=2, n_correspondences=60, batch_size=4, max_hypotheses=8)
    envs.reset(seed=0)
    stacked = 0
    for i in range(12):
        action = envs.action_space.sample()
        action[:, -1] = 1.0 if i % 3 == 2 else -1.0
        _, _, _, _, info = envs.step(action)
        if "batch_samples" in info:  # absent only from the step that resets both (Gymnasium's next-step autoreset)
            stacked += 1
            assert info["batch_samples"].shape == (2, 4, 3) and info["batch_inliers"].shape == (2, 4, 60)
            assert info["batch_count"].shape == (2,)
    assert stacked >= 10
    assert benchmark_vector_step(envs, target_duration=0.05, seed=0) > 0
    envs.close()


def test_all_inlier_drawn_says_whether_a_scored_sample_was_three_true_inliers():
    # Recomputed from the frame's samples as the infos report them, batch by batch, and the frame's true inlier
    # mask: a sample (three row indices) is all-inlier when its three rows are. Frame 1 samples the true inliers
    # only (logits +10 against -10: every sample all-inlier), frame 2 the outliers only (none), frame 3 uniformly.
    env = small(batch_size=4, max_hypotheses=12)
    env.reset(seed=5)
    found = []
    for favour in ("inliers", "outliers", "uniform"):
        inlier = env.current_frame.truth.inlier.copy()
        assert 0 < inlier.sum() < inlier.size
        logits = {"inliers": np.where(inlier, 10.0, -10.0), "outliers": np.where(inlier, -10.0, 10.0),
                  "uniform": np.zeros(inlier.size)}[favour]
        samples, info = [], {"frame_done": False}
        while not info["frame_done"]:  # to the cap: three batches of four
            _, _, _, _, info = env.step(act(env, False, logits))
            samples.append(info["batch_samples"][: info["batch_count"]])
        drawn = np.concatenate(samples)
        assert drawn.shape == (12, 3) == (info["n_hypotheses"], 3)
        every_row_an_inlier = inlier[drawn].all(axis=1)
        assert info["all_inlier_drawn"] is bool(every_row_an_inlier.any())
        found.append((favour, int(every_row_an_inlier.sum())))
    assert found[0] == ("inliers", 12) and found[1] == ("outliers", 0)


@pytest.mark.parametrize("logit_scale", [0.3, 2.5])
def test_sampling_weights_are_the_softmax_of_logit_scale_times_the_action(logit_scale):
    """The docstring's sampling weights ``softmax(logit_scale * a)`` over the valid slots: the
    sampler of the step draws from them (and the frame's selection weighs by them)."""
    env = small(batch_size=4, logit_scale=logit_scale)
    env.reset(seed=5)
    rng = np.random.default_rng(0)
    for _ in range(3):
        n = env.current_frame.n
        logits = rng.uniform(-3.0, 3.0, n).astype(np.float32)  # inside action_bound: no clipping
        env.step(act(env, False, logits))
        search = env.unwrapped._search
        z = logit_scale * logits.astype(np.float64)
        want = np.exp(z - z.max())
        want /= want.sum()
        np.testing.assert_allclose(search.sampler.weights, want, rtol=1e-12, atol=0)
        np.testing.assert_allclose(search.weights, want, rtol=1e-12, atol=0)


TWO_FRAMES = dict(n_frames=2, n_correspondences=40)


def test_render_warns_and_returns_none_as_gymnasium_envs_without_a_render_mode_do(monkeypatch):
    warned = []
    monkeypatch.setattr("gymnasium.logger.warn", lambda message, *a, **k: warned.append(message))
    env = StereoVOAdaptiveEnv(**TWO_FRAMES)
    assert env.render() is None
    env.reset(seed=0)
    assert env.render() is None
    assert warned == ["StereoVOAdaptiveEnv.render() called without a render_mode: the environment has no renderer "
                      "(metadata['render_modes'] is empty), so there is nothing to draw"] * 2
    step_env = StereoVOEnv(**TWO_FRAMES)  # the step environment's behaviour without a render mode
    assert step_env.render() is None and len(warned) == 3


def test_a_pickled_environment_goes_on_bit_for_bit():
    env = StereoVOAdaptiveEnv(**TWO_FRAMES, method="msac+polish+lm")
    env.reset(seed=5)
    action = np.full(env.action_space.shape, 0.5, np.float32)
    action[-1] = -1.0
    env.step(action)
    copy = pickle.loads(pickle.dumps(env))
    assert copy.method == env.method == "msac+polish+lm" and copy.method_options == env.method_options
    for stop in (-1.0, 1.0, -1.0):
        action[-1] = stop
        assert data_equivalence(env.step(action), copy.step(action))


def _frame_rewards(env, seed, stop_after):
    """Each frame's step rewards and its last info, stopping after ``stop_after`` steps (the cap may come first)."""
    env.reset(seed=seed)
    frames, rewards, steps = [], [], 0
    while True:
        action = np.zeros(env.action_space.shape, np.float32)
        action[-1] = 1.0 if steps >= stop_after else -1.0
        _, reward, _, truncated, info = env.step(action)
        rewards.append(reward)
        steps += 1
        if info["frame_done"]:
            frames.append((rewards, info))
            rewards, steps = [], 0
        if truncated:
            return frames


@pytest.mark.parametrize("reward_mode, outlier_ratio", [("supervised", 0.3), ("supervised", 0.99), ("inliers", 0.3),
                                                        ("inliers", 0.99)])
def test_a_frames_rewards_sum_to_the_zero_cost_reward_less_the_cost_of_its_hypotheses(reward_mode, outlier_ratio):
    assert "So a frame's rewards sum to ``r - hypothesis_cost * H``" in " ".join(StereoVOAdaptiveEnv.__doc__.split())
    cost = 0.1
    env = StereoVOAdaptiveEnv(**TWO_FRAMES, outlier_ratio=outlier_ratio, batch_size=4, max_hypotheses=8,
                              hypothesis_cost=cost, reward_mode=reward_mode)
    names = [f.name for f in dataclasses.fields(FrameMetrics) if f.name != "time_s"]
    statuses = []
    for rewards, info in _frame_rewards(env, 0, stop_after=1) + _frame_rewards(env, 1, stop_after=9):
        metrics = FrameMetrics(**{name: info[name] for name in names}, time_s=0.0)
        if reward_mode == "supervised":
            zero_cost = supervised_reward(metrics, env.success_bonus, 0.0, env.failure_reward)
        else:
            zero_cost = inlier_reward(metrics.status == "ok", metrics.n_inliers, TWO_FRAMES["n_correspondences"], 0, 0.0,
                                      env.failure_reward)
        hypotheses = info["frame_hypotheses"]
        assert sum(rewards) == pytest.approx(zero_cost - cost * hypotheses, abs=1e-12)
        assert -1.0 - cost * env.max_hypotheses <= sum(rewards) <= 1.0
        assert all(-1.0 - cost * env.batch_size <= r <= 1.0 for r in rewards)
        if metrics.status != "ok":  # the one-shot environment gives failure_reward flat; here the cost comes on top
            assert sum(rewards) == pytest.approx(-1.0 - cost * hypotheses) and sum(rewards) < -1.0
        statuses.append(metrics.status == "ok")
    assert any(statuses) if outlier_ratio < 0.5 else not all(statuses)  # both kinds of frame are met


def test_the_documented_reward_sum_is_the_one_the_environment_pays():
    doc = " ".join(StereoVOAdaptiveEnv.__doc__.split())
    assert "A frame's rewards sum to the one-shot environment's reward for the same estimate" not in doc
    assert "So a frame's rewards sum to ``r - hypothesis_cost * H``" in doc
    assert "``[-1 - hypothesis_cost * max_hypotheses, 1]``" in doc
    env = StereoVOAdaptiveEnv(**TWO_FRAMES, outlier_ratio=0.99, batch_size=None, max_hypotheses=8, hypothesis_cost=0.1)
    env.reset(seed=0)
    _, reward, _, _, info = env.step(np.zeros(env.action_space.shape, np.float32))
    assert info["status"] != "ok" and reward == pytest.approx(-1.8)  # the docstring's example
    one_shot = StereoVOEnv(**TWO_FRAMES, outlier_ratio=0.99, budget=8, hypothesis_cost=0.1)
    one_shot.reset(seed=0)
    _, reward, _, _, info = one_shot.step(np.zeros(one_shot.action_space.shape, np.float32))
    assert info["status"] != "ok" and reward == -1.0
