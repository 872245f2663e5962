"""vo_gym.rewards against values computed by hand: every mode, the bonus, the failure reward, the hypothesis cost;
and both environments' self-supervised rewards against those functions applied to the estimate the environment made.

Each expected value of the reward functions is written out as arithmetic on literals from the formulas of the
module doc; nothing here asks the code under test for its own expectation. The environments' rewards are then
held to those functions (checked here first) applied to a stubbed estimate known to the test and to the frame's
own measurements, and told apart from the reward the true motion or the true inlier count would earn.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from stereovo.camera import StereoCamera
from stereovo.metrics import FrameMetrics
from vo_gym import StereoVOEnv
from vo_gym.rewards import inlier_reward, msac_reward, pose_error_ratio, supervised_reward


def metrics(**changes) -> FrameMetrics:
    """A frame's metrics: a successful, exact estimate unless ``changes`` say otherwise."""
    base = dict(
        rot_err_deg=0.0, trans_err_m=0.0, t_true_norm_m=1.0, success=True, precision=1.0, recall=1.0,
        n_inliers=100, n_hypotheses=32, n_scored=32, n_point_checks=32 * 200, time_s=0.0, status="ok",
    )
    names = {f.name for f in dataclasses.fields(FrameMetrics)}
    base = {k: v for k, v in base.items() if k in names}
    base.update(changes)
    return FrameMetrics(**base)


# ---------------------------------------------------------------------------- pose error ratio


@pytest.mark.parametrize(
    "rot_deg, trans_m, t_norm, expected",
    [
        (0.5, 0.01, 1.0, 0.5),  # bound max(0.05, 0.05 * 1) = 0.05 m: max(0.5 / 1, 0.01 / 0.05 = 0.2)
        (0.3, 0.15, 2.0, 1.5),  # bound max(0.05, 0.05 * 2) = 0.10 m: 0.15 / 0.10
        (0.2, 0.03, 0.4, 0.6),  # short step: the 5 cm floor, 0.03 / 0.05
        (2.5, 0.0, 1.0, 2.5),  # rotation only: 2.5 deg / 1 deg
    ],
)
def test_pose_error_ratio_uses_the_success_bounds(rot_deg, trans_m, t_norm, expected):
    m = metrics(rot_err_deg=rot_deg, trans_err_m=trans_m, t_true_norm_m=t_norm, success=expected < 1)
    assert pose_error_ratio(m) == pytest.approx(expected, abs=1e-12)


# ---------------------------------------------------------------------------- supervised


def test_supervised_exact_estimate_is_one_minus_the_hypothesis_cost():
    exact = metrics(n_hypotheses=10)
    # 0.5 * 1 + 0.5 * (1 - 0) / (1 + 0) = 1, then 10 hypotheses at 0.01 each.
    assert supervised_reward(exact, success_bonus=0.5, hypothesis_cost=0.0) == pytest.approx(1.0, abs=1e-12)
    assert supervised_reward(exact, success_bonus=0.5, hypothesis_cost=0.01) == pytest.approx(1.0 - 0.1, abs=1e-12)


def test_supervised_defaults_are_half_bonus_no_cost_and_minus_one_on_failure():
    m = metrics(rot_err_deg=0.5, success=True, n_hypotheses=1000)
    # success_bonus 0.5, hypothesis_cost 0: 0.5 + 0.5 * (0.5 / 1.5), the 1000 hypotheses free.
    assert supervised_reward(m) == pytest.approx(0.5 + 0.5 * (0.5 / 1.5), abs=1e-12)
    assert supervised_reward(metrics(status="failed: degenerate sample", success=False)) == -1.0
    assert inlier_reward(True, 50, 100, 1000) == pytest.approx(0.5, abs=1e-12)


def test_supervised_success_below_the_bound():
    m = metrics(rot_err_deg=0.5, trans_err_m=0.01, t_true_norm_m=1.0, success=True, n_hypotheses=32)
    # e = 0.5: 0.5 * 1 + 0.5 * (0.5 / 1.5) = 0.6666..., minus 32 * 0.001.
    assert supervised_reward(m, 0.5, 0.0) == pytest.approx(0.5 + 0.5 * (0.5 / 1.5), abs=1e-12)
    assert supervised_reward(m, 0.5, 0.001) == pytest.approx(0.5 + 0.5 * (0.5 / 1.5) - 0.032, abs=1e-12)
    # Another bonus weight: 0.2 * 1 + 0.8 * (1/3) = 0.4666...
    assert supervised_reward(m, 0.2, 0.0) == pytest.approx(0.2 + 0.8 / 3, abs=1e-12)
    # No bonus: the accuracy term alone.
    assert supervised_reward(m, 0.0, 0.0) == pytest.approx(1 / 3, abs=1e-12)


def test_supervised_miss_earns_no_bonus_and_a_negative_accuracy():
    m = metrics(rot_err_deg=0.3, trans_err_m=0.15, t_true_norm_m=2.0, success=False, n_hypotheses=50)
    # e = 1.5: 0.5 * 0 + 0.5 * (-0.5 / 2.5) = -0.1, minus 50 * 0.002 = 0.1.
    assert supervised_reward(m, 0.5, 0.0) == pytest.approx(-0.1, abs=1e-12)
    assert supervised_reward(m, 0.5, 0.002) == pytest.approx(-0.2, abs=1e-12)
    # The bonus weight scales the accuracy term only: 0.9 * (-0.2) = -0.18.
    assert supervised_reward(m, 0.1, 0.0) == pytest.approx(-0.18, abs=1e-12)


def test_supervised_success_bonus_jumps_at_the_boundary():
    inside = metrics(rot_err_deg=0.999, success=True, n_hypotheses=0)
    outside = metrics(rot_err_deg=1.001, success=False, n_hypotheses=0)
    # Accuracies (1 -/+ ...) are ~0 on both sides; the bonus adds 0.5 * 1 inside only.
    assert supervised_reward(inside, 0.5, 0.0) == pytest.approx(0.5 + 0.5 * (0.001 / 1.999), abs=1e-12)
    assert supervised_reward(outside, 0.5, 0.0) == pytest.approx(0.5 * (-0.001 / 2.001), abs=1e-12)


def test_supervised_useless_estimate_and_the_clip():
    hopeless = metrics(rot_err_deg=float("inf"), trans_err_m=float("inf"), success=False, n_hypotheses=0)
    assert supervised_reward(hopeless, 0.5, 0.0) == pytest.approx(0.5 * -1.0, abs=1e-12)
    huge = metrics(rot_err_deg=1e9, success=False, n_hypotheses=0)
    assert supervised_reward(huge, 0.5, 0.0) == pytest.approx(0.5 * (1 - 1e9) / (1 + 1e9), abs=1e-12)
    # A cost larger than the reward: clipped to -1, never below.
    assert supervised_reward(metrics(n_hypotheses=1000), 0.5, 0.01) == -1.0


def test_supervised_failure_reward_whatever_the_errors():
    failed = metrics(status="failed: too few inliers", success=False, rot_err_deg=0.0, n_hypotheses=32)
    assert supervised_reward(failed, 0.5, 0.001, failure_reward=-0.3) == -0.3
    assert supervised_reward(failed, 0.5, 0.001) == -1.0  # the default failure reward
    assert supervised_reward(failed, 0.5, 0.0, failure_reward=0.25) == 0.25


# ---------------------------------------------------------------------------- inliers


def test_inlier_reward_is_the_inlier_fraction_minus_the_cost():
    assert inlier_reward(True, 120, 200, 32) == pytest.approx(0.6, abs=1e-12)
    assert inlier_reward(True, 120, 200, 32, hypothesis_cost=0.001) == pytest.approx(0.6 - 0.032, abs=1e-12)
    assert inlier_reward(True, 200, 200, 5, hypothesis_cost=0.1) == pytest.approx(0.5, abs=1e-12)
    assert inlier_reward(True, 10, 200, 100, hypothesis_cost=0.05) == -1.0  # 0.05 - 5, clipped
    assert inlier_reward(True, 0, 0, 0) == 0.0  # no matches: no division by zero
    assert inlier_reward(True, 1, 1, 0) == 1.0  # a single match, an inlier: fraction 1 / 1
    assert inlier_reward(False, 120, 200, 32, 0.001, failure_reward=-0.4) == -0.4
    assert inlier_reward(False, 120, 200, 32) == -1.0


# ---------------------------------------------------------------------------- msac


def stereo_pair(camera: StereoCamera):
    """Eight exact matches of points 5-30 m ahead under a known motion ``x_k = R x_{k-1} + t``."""
    X = np.array(
        [[-4.0, -1.0, 12.0], [3.0, 0.5, 8.0], [0.0, 1.2, 20.0], [-2.0, -0.3, 6.0],
         [5.0, 1.0, 25.0], [1.0, -1.5, 15.0], [-6.0, 0.8, 30.0], [2.5, 0.2, 10.0]]
    )
    angle = np.radians(2.0)
    R = np.array([[np.cos(angle), 0, np.sin(angle)], [0, 1, 0], [-np.sin(angle), 0, np.cos(angle)]])
    t = np.array([0.1, 0.0, -1.0])
    return camera.project(X), camera.project(X @ R.T + t), R, t


def test_msac_reward_is_one_for_an_exact_model_minus_the_cost():
    camera = StereoCamera(fx=500.0, fy=480.0, cx=320.0, cy=240.0, baseline=0.3, width=640, height=480)
    prev, curr, R, t = stereo_pair(camera)
    assert msac_reward(True, R, t, prev, curr, camera, 4.0, 10) == pytest.approx(1.0, abs=1e-9)
    assert msac_reward(True, R, t, prev, curr, camera, 4.0, 10, hypothesis_cost=0.002) == pytest.approx(
        1.0 - 0.02, abs=1e-9
    )


def test_msac_reward_counts_rows_without_depth_as_outliers():
    """Rows the k-1 pair cannot triangulate (no disparity, negative disparity, NaN) cost the full gate,
    as an outlier beyond it does; the others are scored as ever."""
    camera = StereoCamera(fx=500.0, fy=480.0, cx=320.0, cy=240.0, baseline=0.3, width=640, height=480)
    prev, curr, R, t = stereo_pair(camera)
    prev = prev.copy()
    prev[0, 2] = prev[0, 0]  # zero disparity
    prev[3, 2] = prev[3, 0] + 2.0  # negative disparity
    prev[5] = np.nan
    assert msac_reward(True, R, t, prev, curr, camera, 4.0, 0) == pytest.approx(5 / 8, abs=1e-9)
    prev[:] = np.nan  # no row has depth: every row an outlier
    assert msac_reward(True, R, t, prev, curr, camera, 4.0, 0) == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("env_id", ["vo_gym/StereoVO-v0", "vo_gym/StereoVOAdaptive-v0"])
def test_the_msac_reward_on_hostile_frames(env_id):
    import gymnasium as gym

    env = gym.make(env_id, reward_mode="msac", outliers="hostile")
    env.reset(seed=0)
    env.action_space.seed(0)
    rewards = []
    for _ in range(12):
        _, reward, terminated, truncated, _ = env.step(env.action_space.sample())
        rewards.append(reward)
        if terminated or truncated:
            env.reset()
    assert np.all(np.isfinite(rewards)) and max(rewards) > 0.0


def test_msac_reward_truncates_each_squared_error_at_the_gate():
    camera = StereoCamera(fx=500.0, fy=480.0, cx=320.0, cy=240.0, baseline=0.3, width=640, height=480)
    prev, curr, R, t = stereo_pair(camera)
    curr = curr.copy()
    curr[[1, 4], 0] += 1.0  # uL off by 1 px: e^2 = 1 px^2 < T^2 = 4, each scores 1 - 1/4
    curr[[2, 6], 1] += 3.0  # vL off by 3 px: e^2 = 9 px^2 > T^2, each scores 0
    expected = (4 * 1.0 + 2 * (1 - 1 / 4) + 2 * 0.0) / 8  # = 0.6875
    assert msac_reward(True, R, t, prev, curr, camera, 4.0, 0) == pytest.approx(expected, abs=1e-9)
    assert msac_reward(True, R, t, prev, curr, camera, 4.0, 20, hypothesis_cost=0.01) == pytest.approx(
        expected - 0.2, abs=1e-9
    )
    # A wider gate T^2 = 16: the 3 px errors now count, 1 - 9/16 each; the 1 px ones 1 - 1/16.
    wide = (4 * 1.0 + 2 * (1 - 1 / 16) + 2 * (1 - 9 / 16)) / 8
    assert msac_reward(True, R, t, prev, curr, camera, 16.0, 0) == pytest.approx(wide, abs=1e-9)
    assert msac_reward(False, R, t, prev, curr, camera, 4.0, 20, failure_reward=-0.6) == -0.6
    assert msac_reward(False, R, t, prev, curr, camera, 4.0, 20) == -1.0  # the default failure reward
    # A single match 1 px off: 1 - 1/4 (the mean over one match, not over two).
    assert msac_reward(True, R, t, prev[1:2], curr[1:2], camera, 4.0, 0) == pytest.approx(0.75, abs=1e-9)


# ---------------------------------------------------------------------------- the environment passes the cost on


@pytest.mark.parametrize("mode", ["supervised", "inliers", "msac"])
def test_env_reward_pays_the_hypothesis_cost_per_hypothesis(mode):
    rewards = {}
    for cost in (0.0, 0.01):
        env = StereoVOEnv(n_frames=2, n_correspondences=120, budget=8, reward_mode=mode, hypothesis_cost=cost,
                          outlier_ratio=0.3, success_bonus=0.5)
        env.reset(seed=4)
        rewards[cost] = [env.step(np.zeros(120))[1] for _ in range(2)]
    # Same seed, same actions, same estimates: 8 hypotheses at 0.01 each (none of the rewards is clipped).
    for free, paid in zip(rewards[0.0], rewards[0.01]):
        assert -0.9 < paid < 1.0
        assert free - paid == pytest.approx(8 * 0.01, abs=1e-9)


# ---------------------------------------------------------------- the self-supervised rewards score the estimate
#
# The estimator is stubbed to return a known estimate, wrong in a known way: the frame's true motion turned by
# YAW_ERROR about the camera's y axis (about 1.25 px at the default focal length of 719 px, whatever the depth: an
# error of the order of the 2.5 px gate, which the score weighs) and the first STUB_INLIERS rows as its inliers.
# The environment's reward must be the reward function of that estimate on the frame's own measurements, under the
# gate threshold_px^2 given to the environment; the true motion or the true inlier count would give another value.

GATE_PX = 2.5
YAW_ERROR = np.radians(0.1)
STUB_INLIERS = 30
REWARD_ENV = dict(n_frames=2, n_correspondences=120, outlier_ratio=0.4, threshold_px=GATE_PX, hypothesis_cost=0.002,
                  failure_reward=-0.5)


def _rot_y(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _stub_the_estimate(monkeypatch, owner, method_name: str, env) -> list:
    """Make ``owner.method_name`` (the environment's estimator call) return the known wrong estimate of the
    frame ``env`` is estimating; returns the list of the estimates handed to the environment."""
    real = getattr(owner, method_name)
    made = []

    def known(self, *args, **kwargs):
        est, frame = real(self, *args, **kwargs), env.current_frame
        inliers = np.zeros(frame.n, dtype=bool)
        inliers[:STUB_INLIERS] = True
        made.append(dataclasses.replace(est, status="ok", rotation=_rot_y(YAW_ERROR) @ frame.truth.rotation,
                                        translation=frame.truth.translation.copy(), inliers=inliers))
        return made[-1]

    monkeypatch.setattr(owner, method_name, known)
    return made


def _frame_rewards(mode: str, frame, est, n_hypotheses: int, cost: float) -> tuple[float, float]:
    """(the reward of the estimate, the reward the truth would earn) on ``frame``, from the reward functions."""
    fail = REWARD_ENV["failure_reward"]
    if mode == "inliers":
        assert np.count_nonzero(est.inliers) == STUB_INLIERS
        return (inlier_reward(True, STUB_INLIERS, frame.n, n_hypotheses, cost, fail),
                inlier_reward(True, int(np.count_nonzero(frame.truth.inlier)), frame.n, n_hypotheses, cost, fail))
    gate_sq = GATE_PX**2
    return (msac_reward(True, est.rotation, est.translation, frame.prev, frame.curr, frame.camera, gate_sq,
                        n_hypotheses, cost, fail),
            msac_reward(True, frame.truth.rotation, frame.truth.translation, frame.prev, frame.curr, frame.camera,
                        gate_sq, n_hypotheses, cost, fail))


def _check_the_msac_gate(frame, est, n_hypotheses: int, cost: float, reward: float) -> None:
    """The reward is not the one a gate 100 times wider (10 times in pixels) would give."""
    wide = msac_reward(True, est.rotation, est.translation, frame.prev, frame.curr, frame.camera, 100 * GATE_PX**2,
                       n_hypotheses, cost, REWARD_ENV["failure_reward"])
    assert abs(wide - reward) > 0.05


@pytest.mark.parametrize("mode", ["inliers", "msac"])
def test_the_envs_self_supervised_reward_scores_the_estimate_it_made(monkeypatch, mode):
    import vo_gym.env as env_module

    env = StereoVOEnv(**REWARD_ENV, budget=8, reward_mode=mode)
    made = _stub_the_estimate(monkeypatch, env_module.PreparedEstimator, "estimate", env)
    env.reset(seed=3)
    for k in (1, 2):
        frame = env.current_frame
        _, reward, _, _, info = env.step(np.zeros(120))
        assert len(made) == k and info["frame"] == k and info["n_hypotheses"] == 8
        expected, from_truth = _frame_rewards(mode, frame, made[-1], 8, 0.002)
        assert reward == pytest.approx(expected, abs=1e-12)
        assert abs(from_truth - expected) > 0.05  # the truth would earn another reward
        if mode == "msac":
            _check_the_msac_gate(frame, made[-1], 8, 0.002, reward)


@pytest.mark.parametrize("mode", ["inliers", "msac"])
def test_the_adaptive_envs_self_supervised_reward_scores_the_estimate_it_made(monkeypatch, mode):
    # Each step costs 0.002 per hypothesis drawn; the step that ends a frame adds the frame's reward without that
    # cost. Frame 1 ends on the agent's stop (a step that draws nothing), frame 2 at the cap (a step that draws).
    from vo_gym.adaptive_env import StereoVOAdaptiveEnv
    from vo_gym.in_frame import InFrameSearch

    env = StereoVOAdaptiveEnv(**REWARD_ENV, batch_size=4, max_hypotheses=8, reward_mode=mode)
    made = _stub_the_estimate(monkeypatch, InFrameSearch, "finish", env)
    env.reset(seed=3)
    go, stop = np.zeros(121, np.float32), np.zeros(121, np.float32)
    go[-1], stop[-1] = -1.0, 1.0
    frame = env.current_frame
    _, reward, _, _, info = env.step(go)
    assert not info["frame_done"] and not made and reward == pytest.approx(-0.002 * 4, abs=1e-12)
    _, reward, _, _, info = env.step(stop)
    assert info["frame_done"] and info["stopped"] and info["batch_count"] == 0 and len(made) == 1
    expected, from_truth = _frame_rewards(mode, frame, made[-1], 0, 0.0)
    assert reward == pytest.approx(expected, abs=1e-12) and abs(from_truth - expected) > 0.05
    if mode == "msac":
        _check_the_msac_gate(frame, made[-1], 0, 0.0, reward)
    frame = env.current_frame
    assert frame.index == 2
    env.step(go)
    _, reward, _, truncated, info = env.step(go)
    assert info["frame_done"] and not info["stopped"] and info["batch_count"] == 4 and truncated and len(made) == 2
    expected, from_truth = _frame_rewards(mode, frame, made[-1], 0, 0.0)
    assert reward == pytest.approx(-0.002 * 4 + expected, abs=1e-12) and abs(from_truth - expected) > 0.05
