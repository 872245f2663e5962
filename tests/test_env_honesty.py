"""The environment chains, features and summarises the *estimate*, never the truth; observations carry no label.

An estimator stub returns a known wrong motion. The estimated poses are then worked out by hand
from that motion alone, the constant-velocity feature of the next step must be that of the
stubbed motion, and the episode's trajectory summary must score those poses. Frames whose
ground truth is permuted or withheld (every label, the true motion and the true poses replaced)
must give bit-identical observations.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from gymnasium.utils.env_checker import data_equivalence

import vo_gym.env as env_module
from stereovo.simulation import Sequence
from vo_gym import StereoVOEnv
from vo_gym.features import compute_features, feature_index

THETA = 0.02  # rad about the camera's y axis (yaw)
WRONG_R = np.array([[np.cos(THETA), 0.0, np.sin(THETA)], [0.0, 1.0, 0.0], [-np.sin(THETA), 0.0, np.cos(THETA)]])
WRONG_T = np.array([-0.3, 0.05, -0.6])  # the true car moves about 1 m forward per frame, no sideways slip
KWARGS = dict(n_frames=4, n_correspondences=120, outlier_ratio=0.4, budget=8)


def rot_y(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def stub_estimator(monkeypatch, fail_at: tuple[int, ...] = ()):
    """Replace the env's estimator call by one returning (WRONG_R, WRONG_T); ``fail_at`` calls (1-based) fail."""
    real = env_module.estimate_problem
    calls = []

    def wrong(problem, **kwargs):
        est = real(problem, **kwargs)
        calls.append(est)
        if len(calls) in fail_at:
            return dataclasses.replace(est, status="failed: stubbed failure", rotation=np.eye(3),
                                       translation=np.zeros(3))
        return dataclasses.replace(est, status="ok", rotation=WRONG_R.copy(), translation=WRONG_T.copy())

    monkeypatch.setattr(env_module, "estimate_problem", wrong)
    return calls


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
    received = []
    real = env_module.estimate_problem

    def spy(problem, **kwargs):
        received.append((kwargs.get("priors"), kwargs.get("order")))
        return real(problem, **kwargs)

    monkeypatch.setattr(env_module, "estimate_problem", spy)
    env = StereoVOEnv(**{**KWARGS, "sampling": sampling, "logit_scale": 0.5, "action_bound": 10.0})
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
    received = []
    real = env_module.estimate_problem

    def spy(problem, **kwargs):
        received.append(kwargs.get("order"))
        return real(problem, **kwargs)

    monkeypatch.setattr(env_module, "estimate_problem", spy)
    env = StereoVOEnv(**{**KWARGS, "sampling": sampling, "logit_scale": 0.5, "action_bound": 10.0,
                         "render_mode": "rgb_array"})
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

    methods = []
    real = env_module.estimate_problem

    def spy(problem, **kwargs):
        methods.append(kwargs.get("method"))
        return real(problem, **kwargs)

    monkeypatch.setattr(env_module, "estimate_problem", spy)
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
        assert str(raised.value) == f"StereoVOEnv: kitti_lengths must be positive numbers (m), got {bad!r}"
