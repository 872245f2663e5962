"""NG-RANSAC's task losses on values by hand, for the survivors of the mutmut run of ``agents/ngransac.py``
(docs/mutation-testing.md). The losses: minus the inlier fraction, plus half the change from the previous
motion in units of 25 cm and 1 degree, capped at 1 (Brachmann & Rother, "Neural-guided RANSAC", ICCV 2019,
for the self-supervised inlier loss).
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
import torch

import agents.ngransac as ngransac
from agents.ngransac import LOSS_CAP, NGRansacConfig, NGRansacTrainer, inlier_loss, pose_loss, smooth_inlier_loss
from stereovo.estimation import MotionEstimate, StereoProblem
from stereovo.estimation.roles.samplers import WeightedSampler
from stereovo.simulation import simulate_frame
from vo_gym.features import compute_features


def _estimate(R, t, n_inliers, n=50, status="ok"):
    inliers = np.zeros(n, dtype=bool)
    inliers[:n_inliers] = True
    return MotionEstimate(R, np.asarray(t, float), inliers, status, 16, 16, 800, 0.0, "msac")


def _yaw(deg):
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def test_inlier_loss_of_a_single_correspondence_frame():
    assert inlier_loss(SimpleNamespace(n_inliers=1), SimpleNamespace(n=1)) == -1.0
    assert inlier_loss(SimpleNamespace(n_inliers=0), SimpleNamespace(n=0)) == 0.0


def test_smoothness_penalty_by_hand():
    frame = SimpleNamespace(n=50)
    previous = (np.eye(3), np.array([0.0, 0.0, -1.0]))
    # 5 cm and 0.2 degrees from the previous motion: change 0.05 / 0.25 + 0.2 / 1 = 0.4, penalty 0.2.
    loss = smooth_inlier_loss(_estimate(_yaw(0.2), [0.0, 0.05, -1.0], 20), frame, previous)
    assert loss == pytest.approx(-0.4 + 0.5 * 0.4, rel=1e-9)
    # 30 cm and 0.5 degrees: change 1.2 + 0.5 = 1.7, capped at 1: penalty 0.5.
    loss = smooth_inlier_loss(_estimate(_yaw(0.5), [0.3, 0.0, -1.0], 20), frame, previous)
    assert loss == pytest.approx(-0.4 + 0.5, rel=1e-12)


def test_pose_loss_in_units_of_the_success_bounds_capped():
    # The bounds: 1 degree, and 5 cm or 5 % of the true translation, whichever is larger.
    truth = SimpleNamespace(rotation=np.eye(3), translation=np.array([0.0, 0.0, -2.0]))
    frame = SimpleNamespace(truth=truth, n=50)
    # 0.3 degrees and 8 cm off a 2 m motion: max(0.3 / 1, 0.08 / 0.1) = 0.8.
    estimate = _estimate(_yaw(0.3), [0.0, 0.08, -2.0], 20)
    assert pose_loss(estimate, frame) == pytest.approx(0.8, rel=1e-9)
    assert ngransac.LOSS_FUNCTIONS["supervised"](estimate, frame, None) == pytest.approx(0.8, rel=1e-9)
    # 0.6 degrees and 1 cm off a 0.5 m motion (bound 5 cm): 0.6, the rotation's.
    short = SimpleNamespace(truth=SimpleNamespace(rotation=np.eye(3), translation=np.array([0.0, 0.0, -0.5])), n=50)
    assert pose_loss(_estimate(_yaw(0.6), [0.01, 0.0, -0.5], 20), short) == pytest.approx(0.6, rel=1e-9)
    # 10 degrees off: 10, capped at 4; a failed estimate costs the cap whatever its motion.
    assert pose_loss(_estimate(_yaw(10.0), [0.0, 0.0, -2.0], 20), frame) == LOSS_CAP == 4.0
    assert pose_loss(_estimate(np.eye(3), [0.0, 0.0, -2.0], 20, status="failed: degenerate"), frame) == 4.0


def test_frame_loss_pools_the_frames_problem_and_the_previous_motions_features(monkeypatch):
    # One training step's objective by hand: K pools of M triplets drawn from the network's softmax over the
    # features of (frame, previous motion), each pool fitted on the frame's own problem (its noise: 2 px, not
    # the default 0.5), the advantage against the pools' mean loss times each pool's draw log-probability
    # (the core sampler's), minus the entropy bonus over log N.
    config = NGRansacConfig(loss="self-supervised-smooth", n_correspondences=60, noise_sigma=2.0, epsilon_range=(0.5, 0.5),
                            budget=3, pools=3, width=8, blocks=1, entropy_weight=0.1, seed=2)
    trainer = NGRansacTrainer(config)
    frame = simulate_frame(config.simulation(0.5), np.random.default_rng(3))
    previous = (_yaw(2.0), np.array([0.4, 0.0, -1.0]))
    net_inputs, net_outputs = [], []

    def record(module, args, out):
        net_inputs.append(args)
        net_outputs.append(out)

    trainer.net.register_forward_hook(record)
    pools = []
    real = ngransac.run_pool

    def spy(problem, samples, *args):
        pools.append((problem, samples.copy(), real(problem, samples, *args)))
        return pools[-1][2]

    monkeypatch.setattr(ngransac, "run_pool", spy)
    objective, losses, success, first = trainer._frame_loss(frame, previous)

    features = compute_features(frame.prev, frame.curr, frame.scores, frame.camera, 2.0, previous)
    assert not np.array_equal(features, compute_features(frame.prev, frame.curr, frame.scores, frame.camera, 2.0))
    (x, mask), = net_inputs
    np.testing.assert_array_equal(x[0].numpy(), features)
    assert mask.shape == (1, 60) and bool(mask.all())  # every row valid
    reference = StereoProblem.build(frame.prev, frame.curr, frame.camera, 2.0)
    assert len(pools) == 3
    for problem, samples, _ in pools:
        assert problem.noise_sigma == 2.0 and samples.shape == (3, 3)
        np.testing.assert_array_equal(problem.cov_prev, reference.cov_prev)
    estimates = [estimate for _, _, estimate in pools]
    assert first is estimates[0]
    # The smooth loss of each pool against the previous motion (2 degrees and 40 cm off: the capped penalty).
    assert losses == [smooth_inlier_loss(e, frame, previous) for e in estimates] and len(set(losses)) > 1
    assert any(loss != inlier_loss(e, frame) for loss, e in zip(losses, estimates))
    assert success == [pose_loss(e, frame) < 1.0 for e in estimates]
    p = torch.softmax(net_outputs[0][0].detach().double(), 0).numpy()
    log_prob = np.array([WeightedSampler(p).log_probability(samples).sum() for _, samples, _ in pools])
    entropy = -np.sum(p * np.log(p)) / np.log(60)
    expected = np.mean((np.array(losses) - np.mean(losses)) * log_prob) - 0.1 * entropy
    assert float(objective.detach()) == pytest.approx(expected, rel=1e-5, abs=1e-7)
    assert objective.requires_grad


def test_frame_loss_of_a_randomised_method_draws_from_the_trainers_rng():
    # R-RANSAC's pre-test picks random points: the pools take them from the trainer's generator, so one seed
    # gives one training step.
    config = NGRansacConfig(loss="self-supervised", method="r-ransac", n_correspondences=60, epsilon_range=(0.5, 0.5),
                            budget=3, pools=2, width=8, blocks=1, seed=4)
    frame = simulate_frame(config.simulation(0.5), np.random.default_rng(5))
    steps = [NGRansacTrainer(config)._frame_loss(frame, None) for _ in range(2)]
    assert steps[0][1] == steps[1][1]
    assert float(steps[0][0].detach()) == float(steps[1][0].detach())


def test_frame_loss_success_is_strictly_under_the_bound(monkeypatch):
    # As frame_metrics' success: a pose error of exactly the bound (ratio 1) is a miss.
    config = NGRansacConfig(loss="self-supervised", n_correspondences=60, epsilon_range=(0.5, 0.5), budget=3, pools=2,
                            width=8, blocks=1, seed=4)
    frame = simulate_frame(config.simulation(0.5), np.random.default_rng(5))
    monkeypatch.setattr(ngransac, "pose_loss", lambda estimate, frame: 1.0)
    assert NGRansacTrainer(config)._frame_loss(frame, None)[2] == [False, False]


def test_triplet_log_prob_stays_finite_when_two_picks_hold_all_the_float32_mass():
    # The trainer's float32 softmax of logits (0, 0, -80): the first two picks sum to exactly 1.0, so the third
    # draw's remaining mass rounds to 0; its log-probability and gradient must stay finite (they are bounded by
    # a floor on the mass left), or one such pool turns the whole policy gradient into inf or NaN.
    logits = torch.tensor([0.0, 0.0, -80.0], requires_grad=True)
    log_p = torch.log_softmax(logits, 0)
    assert float(log_p.detach().exp()[:2].sum()) == 1.0
    value = ngransac.ordered_triplet_log_prob(log_p, torch.tensor([[0, 1, 2], [1, 0, 2]]))
    assert bool(torch.isfinite(value).all())
    value.sum().backward()
    assert bool(torch.isfinite(logits.grad).all())
