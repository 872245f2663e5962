"""The environment chains, features and summarises the *estimate*, never the truth; observations carry no label.

An estimator stub returns a known wrong motion. The estimated poses are then worked out by hand
from that motion alone, the constant-velocity feature of the next step must be that of the
stubbed motion, and the episode's trajectory summary must score those poses. Frames whose
ground truth is permuted or withheld (every label, the true motion and the true poses replaced)
must give bit-identical observations.

The last section pins the rest of the contract value by value, each against a value worked out
independently: the exact messages, the simulator's and estimator's settings, the seeds, the spaces,
the action's validation and clipping, the rewards, and what close() releases.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from gymnasium.utils import seeding
from gymnasium.utils.env_checker import data_equivalence

import vo_gym.env as env_module
from stereovo.camera import StereoCamera
from stereovo.estimation import EstimatorOptions, method_spec
from stereovo.simulation import Sequence
from tests.support.frames import frames_without_depth
from vo_gym import StereoVOEnv
from vo_gym.features import compute_features, feature_index

THETA = 0.02  # rad about the camera's y axis (yaw)
WRONG_R = np.array([[np.cos(THETA), 0.0, np.sin(THETA)], [0.0, 1.0, 0.0], [-np.sin(THETA), 0.0, np.cos(THETA)]])
WRONG_T = np.array([-0.3, 0.05, -0.6])  # the true car moves about 1 m forward per frame, no sideways slip
KWARGS = dict(n_frames=4, n_correspondences=120, outlier_ratio=0.4, budget=8)


def rot_y(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _call_kwargs(estimator, priors, order, rng) -> dict:
    """One estimate's arguments as :func:`stereovo.estimation.estimate_problem` would take them:
    the prepared estimator's method and options, and the step's priors, order and generator."""
    return {"method": estimator.method, "priors": priors, "order": order, "rng": rng, **estimator.options}


def stub_estimator(monkeypatch, fail_at: tuple[int, ...] = ()):
    """Replace the env's estimator call by one returning (WRONG_R, WRONG_T); ``fail_at`` calls (1-based) fail."""
    real = env_module.PreparedEstimator.estimate
    calls = []

    def wrong(self, problem, priors=None, order=None, rng=0):
        est = real(self, problem, priors=priors, order=order, rng=rng)
        calls.append(est)
        if len(calls) in fail_at:
            return dataclasses.replace(est, status="failed: stubbed failure", rotation=np.eye(3),
                                       translation=np.zeros(3))
        return dataclasses.replace(est, status="ok", rotation=WRONG_R.copy(), translation=WRONG_T.copy())

    monkeypatch.setattr(env_module.PreparedEstimator, "estimate", wrong)
    return calls


def spy_estimator(monkeypatch, read):
    """Record ``read(kwargs)`` of every estimator call the env makes (before the estimator runs; ``kwargs``
    as :func:`_call_kwargs` gives them), then run the real one; returns the list the records go to."""
    real = env_module.PreparedEstimator.estimate
    received = []

    def spy(self, problem, priors=None, order=None, rng=0):
        received.append(read(_call_kwargs(self, priors, order, rng)))
        return real(self, problem, priors=priors, order=order, rng=rng)

    monkeypatch.setattr(env_module.PreparedEstimator, "estimate", spy)
    return received


def hand_chained_poses(motions: list[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
    """Camera-to-world poses from the identity under ``x_k = R x_{k-1} + t``: O_k = O_{k-1} R^T,
    c_k = c_{k-1} - O_{k-1} R^T t (the camera centre at k is -R^T t in frame k-1's coordinates)."""
    O, c = np.eye(3), np.zeros(3)
    poses = [np.eye(4)]
    for R, t in motions:
        c = c - O @ R.T @ t
        O = O @ R.T
        pose = np.eye(4)
        pose[:3, :3], pose[:3, 3] = O, c
        poses.append(pose)
    return np.array(poses)


def test_estimated_poses_and_summary_follow_the_estimate(monkeypatch):
    stub_estimator(monkeypatch)
    env = StereoVOEnv(**KWARGS)
    env.reset(seed=7)
    truncated, info = False, {}
    while not truncated:
        _, _, _, truncated, info = env.step(np.zeros(120))
    est = env.estimated_poses
    # With a constant motion the hand chaining has a closed form too: O_k = R_y(-k theta),
    # c_k = -sum_{j=1..k} R_y(-j theta) t.
    for k in range(5):
        np.testing.assert_allclose(est[k][:3, :3], rot_y(-k * THETA), atol=1e-12)
        np.testing.assert_allclose(est[k][:3, 3], -sum((rot_y(-j * THETA) @ WRONG_T for j in range(1, k + 1)),
                                                       np.zeros(3)), atol=1e-12)
    np.testing.assert_allclose(est, hand_chained_poses([(WRONG_R, WRONG_T)] * 4), atol=1e-12)
    # The summary scores those poses against the truth: the raw ATE is the RMS of the centre errors.
    true = env.sequence.true_poses[:5]
    ate_raw = np.sqrt(np.mean(np.sum((est[:, :3, 3] - true[:, :3, 3]) ** 2, axis=1)))
    summary = info["trajectory"]
    assert summary["ate_raw_m"] == pytest.approx(ate_raw, rel=1e-9)
    assert summary["ate_raw_m"] > 0.5  # 0.3 m sideways per frame: far from the truth
    assert summary["n_poses"] == 5 and summary["failed_frames"] == 0
    # The true path length is the truth's, whatever the estimate.
    steps = np.linalg.norm(np.diff(true[:, :3, 3], axis=0), axis=1)
    assert summary["path_length_m"] == pytest.approx(float(np.sum(steps)), rel=1e-9)


def test_a_failed_frame_chains_the_last_estimate_not_the_truth(monkeypatch):
    stub_estimator(monkeypatch, fail_at=(1, 3))
    env = StereoVOEnv(**KWARGS)
    env.reset(seed=7)
    infos = [env.step(np.zeros(120))[4] for _ in range(4)]
    assert [i["fallback"] for i in infos] == [True, False, True, False]
    # Frame 1 fails with no motion known yet: identity. Frame 3 fails: the last estimate (the stub's) again.
    expected = hand_chained_poses([(np.eye(3), np.zeros(3))] + [(WRONG_R, WRONG_T)] * 3)
    np.testing.assert_allclose(env.estimated_poses, expected, atol=1e-12)
    assert infos[-1]["trajectory"]["failed_frames"] == 2


def test_next_observations_constant_velocity_feature_uses_the_estimate(monkeypatch):
    stub_estimator(monkeypatch)
    env = StereoVOEnv(**KWARGS)
    obs, _ = env.reset(seed=7)
    cv, available = feature_index("cv_residual"), feature_index("cv_available")
    assert np.all(obs["features"][:, cv] == 0) and np.all(obs["features"][:, available] == 0)
    first_truth = env.current_frame.truth
    obs, *_ = env.step(np.zeros(120))
    frame = env.current_frame  # frame 2, the one the observation describes
    sigma = env.estimator_noise_sigma
    from_estimate = compute_features(frame.prev, frame.curr, frame.scores, frame.camera, sigma, (WRONG_R, WRONG_T))
    from_truth = compute_features(frame.prev, frame.curr, frame.scores, frame.camera, sigma,
                                  (first_truth.rotation, first_truth.translation))
    np.testing.assert_array_equal(obs["features"][:, cv], from_estimate[:, cv])
    assert np.all(obs["features"][:, available] == 1)
    # And it is not the truth's: a 0.3 m sideways error moves every match by pixels.
    assert np.median(from_estimate[:, cv]) > np.median(from_truth[:, cv]) + 0.5


# ---------------------------------------------------------------------------- labels permuted or withheld


class _PermutedTruth(Sequence):
    """The same measurements; the labels of every frame permuted."""

    def frame(self, k):
        frame = super().frame(k)
        perm = np.random.default_rng(500 + k).permutation(frame.n)
        truth = dataclasses.replace(frame.truth, inlier=frame.truth.inlier[perm],
                                    outlier_kind=frame.truth.outlier_kind[perm])
        return dataclasses.replace(frame, truth=truth)


class _WithheldTruth(Sequence):
    """The same measurements; every ground-truth value the environment can see replaced by an uninformative one:
    the true poses it reads (identity) and each frame's labels, motion and poses."""

    def __init__(self, config, seed=None):
        super().__init__(config, seed)
        self._hidden_poses = self.true_poses  # the frames are still rendered from the real trajectory
        poses = np.broadcast_to(np.eye(4), np.shape(self.true_poses)).copy()
        poses.flags.writeable = False
        self.true_poses = poses

    def frame(self, k):
        shown, self.true_poses = self.true_poses, self._hidden_poses
        try:
            frame = super().frame(k)
        finally:
            self.true_poses = shown
        truth = dataclasses.replace(
            frame.truth, rotation=np.eye(3), translation=np.zeros(3), inlier=np.ones(frame.n, dtype=bool),
            outlier_kind=np.zeros(frame.n, dtype=np.int8), pose_prev=np.eye(4), pose_curr=np.eye(4),
            outlier_ratio=0.0,
        )
        return dataclasses.replace(frame, truth=truth)


def _observations(n_steps=4, **kwargs):
    env = StereoVOEnv(**{**KWARGS, **kwargs})
    obs, _ = env.reset(seed=13)
    out = [obs]
    actions = np.random.default_rng(0).uniform(-3, 3, (n_steps, 120))
    for a in actions:
        obs, *_ = env.step(a)
        out.append(obs)
    return out


@pytest.mark.parametrize("sequence_cls", [_PermutedTruth, _WithheldTruth])
@pytest.mark.parametrize("sampling", ["guided", "prosac"])
def test_observations_ignore_the_labels(monkeypatch, sequence_cls, sampling):
    plain = _observations(sampling=sampling)
    monkeypatch.setattr(env_module, "Sequence", sequence_cls)
    relabelled = _observations(sampling=sampling)
    assert len(plain) == len(relabelled) == 5
    for k, (a, b) in enumerate(zip(plain, relabelled)):
        assert data_equivalence(a, b, exact=True), f"observation {k} differs"


def test_observation_carries_the_match_scores_and_their_ranks():
    # Columns 0 and 1 by hand: the frame's own scores (float32), and rank / (N - 1) with 0 the best score.
    env = StereoVOEnv(**KWARGS)
    obs, _ = env.reset(seed=3)
    scores = env.current_frame.scores
    features = obs["features"]
    np.testing.assert_array_equal(features[:, feature_index("match_score")], scores.astype(np.float32))
    rank = np.empty(120)
    rank[np.argsort(-scores)] = np.arange(120)
    np.testing.assert_allclose(features[:, feature_index("score_rank")], rank / 119, atol=1e-7)
    assert features[np.argmax(scores), feature_index("score_rank")] == 0.0
    assert features[np.argmin(scores), feature_index("score_rank")] == 1.0


@pytest.mark.parametrize("sampling", ["guided", "prosac"])
def test_the_estimator_receives_the_agents_weights_or_order(monkeypatch, sampling):
    calls = stub_estimator(monkeypatch)
    received = spy_estimator(monkeypatch, lambda kwargs: (kwargs.get("priors"), kwargs.get("order")))
    scale = {"logit_scale": 0.5} if sampling == "guided" else {}  # PROSAC's order takes no scale
    env = StereoVOEnv(**{**KWARGS, "sampling": sampling, **scale, "action_bound": 10.0})
    env.reset(seed=1)
    action = np.random.default_rng(0).uniform(-6, 6, 120)
    action[[3, 4]] = 2.0  # a tie: the stable order keeps 3 before 4
    env.step(action)
    priors, order = received[0]
    assert len(calls) == 1
    if sampling == "guided":
        assert order is None
        # softmax(logit_scale * a): the ratio of two priors is exp(0.5 (a_i - a_j)).
        np.testing.assert_allclose(priors / priors[0], np.exp(0.5 * (action - action[0])), rtol=1e-9)
        assert np.max(priors) == pytest.approx(1.0)  # shifted by the largest logit, no overflow
    else:
        assert priors is None
        np.testing.assert_array_equal(order, np.argsort(-action, kind="stable"))
        assert list(order).index(3) < list(order).index(4) and action[order[0]] == np.max(action)


def test_stepping_out_of_turn_names_the_fix():
    env = StereoVOEnv(**{**KWARGS, "n_frames": 1})
    with pytest.raises(RuntimeError, match=r"^StereoVOEnv: call reset\(\) before step\(\)$"):
        env.step(np.zeros(120))
    env.reset(seed=0)
    env.step(np.zeros(120))
    with pytest.raises(RuntimeError, match=r"^StereoVOEnv: the episode is over \(truncated\); call reset\(\)$"):
        env.step(np.zeros(120))


def test_the_episode_summary_drifts_over_the_envs_kitti_lengths(monkeypatch):
    # A 2 m segment fits the 4-frame episode (about 1 m per frame; the default 100-800 m ones do not): one
    # segment, from frame 0 to the first frame 2 m along the true path, whose drift is that frame's pose
    # error inv(P_e) Q_e (P_0 = Q_0 = I) over 2 m.
    stub_estimator(monkeypatch)
    env = StereoVOEnv(**{**KWARGS, "kitti_lengths": (2.0,)})
    env.reset(seed=7)
    truncated, info = False, {}
    while not truncated:
        _, _, _, truncated, info = env.step(np.zeros(120))
    est, true = env.estimated_poses, env.sequence.true_poses[:5]
    along = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(true[:, :3, 3], axis=0), axis=1))])
    assert along[-1] > 2.0
    end = int(np.argmax(along >= 2.0))
    error = np.linalg.inv(est[end]) @ true[end]
    summary = info["trajectory"]
    assert summary["kitti_segments"] == 1
    assert summary["kitti_t_percent"] == pytest.approx(100 * np.linalg.norm(error[:3, 3]) / 2.0, rel=1e-9)


@pytest.mark.parametrize("sampling", ["guided", "prosac"])
def test_render_shows_the_sampling_weights_relative_to_uniform(monkeypatch, sampling):
    # guided: N softmax(logit_scale a), mean 1; prosac: 1 for the first of the order down to 0 for the last,
    # the order by value with ties by row (integer actions: many ties).
    import vo_gym.rendering as rendering

    drawn = []
    monkeypatch.setattr(rendering, "render_rgb", lambda est, true, frame, weights, inliers, title: drawn.append(weights))
    received = spy_estimator(monkeypatch, lambda kwargs: kwargs.get("order"))
    scale = {"logit_scale": 0.5} if sampling == "guided" else {}  # PROSAC's order takes no scale
    env = StereoVOEnv(**{**KWARGS, "sampling": sampling, **scale, "action_bound": 10.0, "render_mode": "rgb_array"})
    env.reset(seed=1)
    action = np.random.default_rng(0).integers(-3, 4, 120).astype(float)
    env.step(action)
    env.render()
    (weights,) = drawn
    if sampling == "guided":
        expected = 120 * np.exp(0.5 * action) / np.sum(np.exp(0.5 * action))
        np.testing.assert_allclose(weights, expected, rtol=1e-9)
    else:
        by_rank = sorted(range(120), key=lambda i: (-action[i], i))
        np.testing.assert_array_equal(received[0], by_rank)
        np.testing.assert_allclose(weights[by_rank], 1.0 - np.arange(120) / 119, rtol=0, atol=1e-15)


def test_render_draws_the_poses_so_far_and_the_frame_just_estimated(monkeypatch):
    # Before a step: the current frame, grey (no weights, no inliers); after one: the frame the step estimated,
    # its weights and the estimate's inliers, with the estimated and true poses so far and the title.
    import re

    import vo_gym.rendering as rendering

    drawn = []
    monkeypatch.setattr(rendering, "render_rgb", lambda *args, **kwargs: drawn.append((args, kwargs)) or "image")
    calls = stub_estimator(monkeypatch)
    env = StereoVOEnv(**{**KWARGS, "render_mode": "rgb_array"})
    with pytest.raises(RuntimeError, match=r"^StereoVOEnv: call reset\(\) before render\(\)$"):
        env.render()
    env.reset(seed=3)
    first = env.current_frame
    assert env.render() == "image"
    (est, true, frame, weights, inliers), kwargs = drawn[-1]
    assert frame is first and weights is None and inliers is None and kwargs == {"title": "frame 1/4 (guided)"}
    np.testing.assert_array_equal(est, np.eye(4)[None])
    np.testing.assert_array_equal(true, env.sequence.true_poses[:1])
    env.step(np.zeros(120))
    env.render()
    (est, true, frame, weights, inliers), kwargs = drawn[-1]
    assert frame is first and kwargs == {"title": "frame 1/4 (guided)"}
    np.testing.assert_array_equal(inliers, calls[0].inliers)
    np.testing.assert_allclose(weights, np.ones(120), rtol=1e-12)  # a zero action: uniform weights
    np.testing.assert_allclose(est, hand_chained_poses([(WRONG_R, WRONG_T)]), atol=1e-12)
    np.testing.assert_array_equal(true, env.sequence.true_poses[:2])
    # Without a render mode: a warning that names the fix, and no image.
    with pytest.warns(UserWarning) as warned:
        assert StereoVOEnv(**KWARGS).render() is None
    text = re.sub(r"\x1b\[[0-9;]*m", "", str(warned[0].message)).removeprefix("WARN: ")
    assert text == "StereoVOEnv.render() called without a render_mode; make the env with render_mode='rgb_array'"


def test_step_info_names_the_frame_its_pose_error_ratio_and_outlier_ratio_and_the_method_is_the_envs(monkeypatch):
    from stereovo.metrics import pose_error_ratio

    methods = spy_estimator(monkeypatch, lambda kwargs: kwargs.get("method"))
    env = StereoVOEnv(**{**KWARGS, "method": "ransac"})
    _, info0 = env.reset(seed=5)
    assert info0 == {"frame": 1}
    for k in (1, 2):
        truth = env.current_frame.truth
        _, _, _, _, info = env.step(np.zeros(120))
        assert info["frame"] == k
        assert info["outlier_ratio"] == float(truth.outlier_ratio) and 0 < info["outlier_ratio"] < 1
        assert info["pose_error_ratio"] == pytest.approx(
            pose_error_ratio(info["rot_err_deg"], info["trans_err_m"], float(np.linalg.norm(truth.translation))), rel=1e-12)
    assert methods == ["ransac", "ransac"]


def test_the_documented_defaults_and_the_kitti_lengths_check():
    env = StereoVOEnv()
    c = env.sim_config
    assert (c.n_frames, c.n_correspondences, c.z_min, c.z_max) == (100, 500, 3.0, 60.0)
    assert (env.budget, env.batch_size, env.action_bound, env.logit_scale, env.hypothesis_cost) == (32, 32, 10.0, 1.0, 0.001)
    assert StereoVOEnv(kitti_lengths=(0.5,)).kitti_lengths == (0.5,)  # any positive length, under 1 m too
    for bad in ((), (0.0,), (-2.0,), (float("nan"),), ("a",)):
        with pytest.raises(ValueError) as raised:
            StereoVOEnv(kitti_lengths=bad)
        assert str(raised.value) == ("StereoVOEnv: kitti_lengths must be a non-empty list, tuple or 1-D array of "
                                     f"positive numbers (m), got {bad!r}")


# ------------------------- the contract, value by value: messages, settings, seeds, spaces, actions, rewards, close

def test_every_simulator_keyword_reaches_the_simulator():
    camera = StereoCamera(fx=700.0, fy=700.0, baseline=0.6)
    given = dict(preset="free", world="open", n_frames=3, n_correspondences=50, noise_sigma=0.7,
                 outlier_ratio=(0.2, 0.3), outlier_mix=(0.5, 0.3, 0.2), score_auc=0.65, z_min=4.0, z_max=40.0,
                 camera=camera, speed=0.8)
    env = StereoVOEnv(**given)
    for name, value in given.items():
        assert getattr(env.sim_config, name) == value, name
    assert env.sim_config.camera is camera
    # One spare frame pair for the observation at truncation, no more.
    env.reset(seed=0)
    assert env.sequence.config == dataclasses.replace(env.sim_config, n_frames=4)


def test_reset_derives_the_frames_and_the_sampler_from_the_seed_as_documented(monkeypatch):
    received = spy_estimator(monkeypatch, lambda kwargs: kwargs["rng"].bit_generator.state)  # before the estimator draws from it
    env = StereoVOEnv(**KWARGS)
    # Seed 5's draws change if the bound 2**63 - 1 changes by one, seed 2's if the low 0 becomes 1.
    for seed in (5, 2):
        rng, _ = seeding.np_random(seed)
        sequence_seed, ransac_seed = (int(rng.integers(0, 2**63 - 1)) for _ in range(2))
        env.reset(seed=seed)
        assert env.sequence.seed == sequence_seed
        env.step(np.zeros(120))
        assert received[-1] == np.random.default_rng(ransac_seed).bit_generator.state


def test_a_noise_free_simulator_needs_the_estimators_noise_and_says_so():
    message = ("StereoVOEnv: noise_sigma=0 (noise-free frames) needs estimator_noise_sigma > 0: "
               "the estimator's gates and the features' uncertainties need a positive pixel noise")
    with pytest.raises(ValueError) as err:
        StereoVOEnv(**{**KWARGS, "noise_sigma": 0.0})
    assert str(err.value) == message
    assert StereoVOEnv(**{**KWARGS, "noise_sigma": 0.0, "estimator_noise_sigma": 0.4}).estimator_noise_sigma == 0.4


def test_batch_size_defaults_to_the_budget_or_to_the_estimators_default():
    assert StereoVOEnv(**KWARGS).estimator_kwargs["batch_size"] == 8
    adaptive = StereoVOEnv(**{**KWARGS, "budget": None})
    assert adaptive.estimator_kwargs["batch_size"] == EstimatorOptions.batch_size == 128
    assert adaptive.estimator_kwargs["budget"] is None
    assert StereoVOEnv(**{**KWARGS, "batch_size": 4}).estimator_kwargs["batch_size"] == 4


@pytest.mark.parametrize("method", ["msac", "mlesac"])
def test_an_unknown_keyword_lists_the_methods_options_without_the_environments_own(method):
    shared = sorted({f.name for f in dataclasses.fields(EstimatorOptions)} - {"noise_sigma", "budget", "batch_size"})
    allowed = sorted({*shared, *method_spec(method).extra_options})
    with pytest.raises(TypeError) as err:
        StereoVOEnv(**KWARGS, method=method, not_an_option=1)
    assert str(err.value) == (
        f"StereoVOEnv got unexpected keyword argument(s) ['not_an_option']: not an environment or simulator "
        f"argument nor an option of estimator method {method!r} (its options: {allowed})")
    assert "noise_sigma" not in allowed and ("mlesac_em_iterations" in allowed) == (method == "mlesac")


def test_a_method_that_samples_nothing_refuses_guided_weights():
    with pytest.raises(ValueError) as err:
        StereoVOEnv(**KWARGS, method="inlier-detection", sampling="guided")
    assert str(err.value) == (
        "StereoVOEnv: estimator method 'inlier-detection' with sampling='guided': method 'inlier-detection' does "
        "not sample hypotheses: priors= and order= have no role in it; pass neither")


def test_invalid_environment_options_name_the_environment():
    with pytest.raises(ValueError) as err:
        StereoVOEnv(**KWARGS, sampling="random")
    assert str(err.value) == "StereoVOEnv: sampling must be one of 'guided', 'prosac', got 'random'"


def test_the_weights_bound_is_300_inclusive_and_its_message_gives_the_product():
    assert StereoVOEnv(**KWARGS, action_bound=30.0, logit_scale=10.0).action_bound == 30.0  # exactly 300
    for bound, scale, product in ((20.0, 20.0, "400"), (10.0, 30.05, "300.5")):
        with pytest.raises(ValueError) as err:
            StereoVOEnv(**KWARGS, action_bound=bound, logit_scale=scale)
        assert str(err.value) == ("StereoVOEnv: action_bound * logit_scale must be <= 300 (weights exp(+-300) stay "
                                  f"representable), got {product}")


def test_spaces_are_float32_and_symmetric():
    env = StereoVOEnv(**KWARGS, action_bound=3.0, max_correspondences=130)
    assert env.observation_space["features"].dtype == np.float32
    assert env.action_space.dtype == np.float32
    np.testing.assert_array_equal(env.action_space.low, np.full(130, -3.0, dtype=np.float32))
    np.testing.assert_array_equal(env.action_space.high, np.full(130, 3.0, dtype=np.float32))


def test_before_the_first_reset_the_env_has_no_episode():
    env = StereoVOEnv(**KWARGS)
    assert env.sequence is None and env.current_frame is None and env.frame_index == 0
    assert env.estimated_poses.shape == (0,) and env.true_poses.shape == (0, 4, 4)


def test_padded_observations_are_float32_and_keep_the_frames_features():
    padded, _ = StereoVOEnv(**KWARGS, max_correspondences=130).reset(seed=4)
    plain, _ = StereoVOEnv(**KWARGS).reset(seed=4)
    assert padded["features"].dtype == np.float32 and padded["features"].shape == (130, plain["features"].shape[1])
    np.testing.assert_array_equal(padded["features"][:120], plain["features"])
    np.testing.assert_array_equal(padded["features"][120:], 0.0)
    np.testing.assert_array_equal(padded["mask"], np.r_[np.ones(120), np.zeros(10)])


def _spy_priors(monkeypatch):
    return spy_estimator(monkeypatch, lambda kwargs: kwargs["priors"])


def test_rows_without_depth_are_masked_and_take_any_action_value(monkeypatch):
    received = _spy_priors(monkeypatch)
    frames_without_depth(monkeypatch, [5, 9])
    env = StereoVOEnv(**KWARGS)
    obs, _ = env.reset(seed=2)
    np.testing.assert_array_equal(np.flatnonzero(obs["mask"] == 0), [5, 9])
    action = np.zeros(120)
    action[0] = 2.0
    action[5], action[9] = np.nan, np.inf
    env.step(action)
    # The non-finite rows get the lowest value, -action_bound: weight exp(-10 - 2) relative to the best row.
    expected = np.exp(action.clip(-10, 10) - 2.0)
    expected[[5, 9]] = np.exp(-10.0 - 2.0)
    np.testing.assert_allclose(received[0], expected, rtol=1e-12)


def test_a_non_finite_value_in_a_valid_slot_is_refused_by_count_and_first_slot(monkeypatch):
    def second_step(action):
        env = StereoVOEnv(**KWARGS, max_correspondences=125)
        env.reset(seed=2)
        padded = np.zeros(125)
        padded[[120, 124]] = np.nan  # padding: ignored
        env.step(padded)
        with pytest.raises(ValueError) as err:
            env.step(action)
        return str(err.value)

    action = np.zeros(125)
    action[[7, 11, 30]] = [np.inf, 0.0, np.nan]
    assert second_step(action) == "StereoVOEnv: the action has NaN or inf in 2 valid slot(s) (first: slot 7)"
    # With rows without depth, only the usable ones count.
    frames_without_depth(monkeypatch, [7, 11])
    action[11] = np.nan
    assert second_step(action) == "StereoVOEnv: the action has NaN or inf in 1 valid slot(s) (first: slot 30)"


def test_action_values_are_clipped_to_the_box_on_both_sides(monkeypatch):
    received = _spy_priors(monkeypatch)
    env = StereoVOEnv(**KWARGS, action_bound=2.0)
    env.reset(seed=2)
    action = np.zeros(120)
    action[:3] = [50.0, -50.0, 1.0]
    env.step(action)
    np.testing.assert_allclose(received[0][:4], np.exp(np.array([2.0, -2.0, 1.0, 0.0]) - 2.0), rtol=1e-12)


def test_complex_and_non_numeric_actions_are_refused_by_type():
    env = StereoVOEnv(**KWARGS)
    env.reset(seed=2)
    with pytest.raises(ValueError) as err:
        env.step(np.zeros(120, dtype=complex))
    assert str(err.value) == "StereoVOEnv: the action must be real values, got complex dtype complex128"
    with pytest.raises(ValueError) as err:
        env.step(["left"] * 120)
    assert str(err.value) == "StereoVOEnv: the action must be a numeric array of shape (120,), got list"


def test_the_supervised_reward_by_hand():
    env = StereoVOEnv(**KWARGS, success_bonus=0.3, hypothesis_cost=0.01)
    env.reset(seed=5)
    _, reward, _, _, info = env.step(np.zeros(120))
    e = info["pose_error_ratio"]
    expected = 0.3 * info["success"] + 0.7 * (1 - e) / (1 + e) - 0.01 * info["n_hypotheses"]
    assert info["status"] == "ok" and reward == pytest.approx(expected, abs=1e-12)


@pytest.mark.parametrize("reward_mode", ["inliers", "msac"])
def test_a_failed_frame_gets_the_envs_failure_reward(monkeypatch, reward_mode):
    stub_estimator(monkeypatch, fail_at=(1,))
    env = StereoVOEnv(**KWARGS, reward_mode=reward_mode, failure_reward=-0.25)
    env.reset(seed=5)
    _, reward, _, _, info = env.step(np.zeros(120))
    assert info["fallback"] and reward == -0.25


def test_close_releases_the_episode_and_a_reset_starts_afresh():
    # close() drops the sequence and the current frame: no sequence, no true poses, and stepping or rendering
    # asks for a reset again, as before the first one; a reset then gives what a fresh environment gives
    env = StereoVOEnv(**{**KWARGS, "render_mode": "rgb_array"})
    first, _ = env.reset(seed=3)
    env.step(np.zeros(120))
    env.close()
    assert env.sequence is None and env.current_frame is None and env.true_poses.shape == (0, 4, 4)
    with pytest.raises(RuntimeError, match=r"^StereoVOEnv: call reset\(\) before step\(\)$"):
        env.step(np.zeros(120))
    with pytest.raises(RuntimeError, match=r"^StereoVOEnv: call reset\(\) before render\(\)$"):
        env.render()
    again, info = env.reset(seed=3)
    assert info == {"frame": 1} and data_equivalence(again, first)
    assert env.sequence is not None and env.current_frame.index == 1 and env.true_poses.shape == (1, 4, 4)
