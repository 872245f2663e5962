"""agents.ngransac, the learned one-shot sampler: equivariance, padding, the policy-gradient estimator,
checkpoints, training, and domain randomisation (each sequence draws its own match-error process)."""

from __future__ import annotations

import itertools
import math
from types import SimpleNamespace

import numpy as np
import pytest
import torch

import agents.ngransac as ngransac
from agents.checkpoint import LearnedPolicy, load_checkpoint, save_checkpoint
from agents.network import CorrespondenceNet
from agents.ngransac import (
    NGRansacConfig,
    NGRansacTrainer,
    ordered_triplet_log_prob,
    RANDOMISED_AUC,
    randomised_frame_stream,
    LOSS_CAP,
    inlier_loss,
    pose_loss,
    smooth_inlier_loss,
)
from stereovo.estimation import MotionEstimate, StereoProblem
from stereovo.estimation.roles.samplers import WeightedSampler
from stereovo.simulation import simulate_frame
from vo_gym.features import N_FEATURES, compute_features


def _inlier_mass(net, frames) -> float:
    """Mean probability the network puts on the true inliers (test-only: reads labels)."""
    from vo_gym.features import compute_features

    masses = []
    with torch.no_grad():
        for frame in frames:
            feats = compute_features(frame.prev, frame.curr, frame.scores, frame.camera, frame.noise_sigma)
            p = torch.softmax(net(torch.from_numpy(feats)[None], torch.ones(1, frame.n, dtype=torch.bool))[0], 0)
            masses.append(float(p[torch.from_numpy(frame.truth.inlier)].sum()))
    return float(np.mean(masses))


def first_frames(seed: int, sequences: int = 6):
    stream = randomised_frame_stream(NGRansacConfig(domain_randomisation=True, frames_per_sequence=2), seed)
    return list(itertools.islice(stream, 0, 2 * sequences, 2))


def test_network_is_permutation_equivariant_and_padding_independent():
    torch.manual_seed(0)
    net = CorrespondenceNet(N_FEATURES, width=16, blocks=2).eval()
    x = torch.randn(1, 50, N_FEATURES)
    mask = torch.ones(1, 50, dtype=torch.bool)
    logits = net(x, mask)
    perm = torch.randperm(50)
    torch.testing.assert_close(net(x[:, perm], mask)[0], logits[0, perm], atol=1e-5, rtol=1e-5)
    # Pad with garbage rows: the valid logits must not move.
    padded = torch.cat([x, 100 * torch.randn(1, 30, N_FEATURES)], dim=1)
    padded_mask = torch.cat([mask, torch.zeros(1, 30, dtype=torch.bool)], dim=1)
    out = net(padded, padded_mask)
    torch.testing.assert_close(out[0, :50], logits[0], atol=1e-5, rtol=1e-5)
    assert torch.all(out[0, 50:] < -1e3)
    # Same weights, any N.
    assert net(torch.randn(2, 7, N_FEATURES), torch.ones(2, 7, dtype=torch.bool)).shape == (2, 7)


def test_ordered_triplet_log_prob_matches_core_sampler():
    p = np.array([0.4, 0.3, 0.2, 0.05, 0.05])
    samples = np.array([[0, 1, 2], [4, 3, 0], [2, 0, 1]])
    ours = ordered_triplet_log_prob(torch.log(torch.tensor(p)), torch.from_numpy(samples)).numpy()
    np.testing.assert_allclose(ours, WeightedSampler(p).log_probability(samples), rtol=1e-9)


def test_policy_gradient_raises_probability_of_all_inlier_sets():
    # Toy frame: 12 correspondences, the first 4 are inliers; a pool "succeeds" (loss 0)
    # when one of its triplets is all-inlier. The score-function estimator with the
    # mean-of-pools baseline must push probability mass onto the inliers.
    torch.manual_seed(0)
    rng = np.random.default_rng(0)
    logits = torch.zeros(12, requires_grad=True)
    opt = torch.optim.SGD([logits], lr=0.5)
    inlier = np.arange(12) < 4

    def all_inlier_probability() -> float:
        p = torch.softmax(logits.detach().double(), 0).numpy()
        q = WeightedSampler(p)
        triplets = np.array([(a, b, c) for a in range(4) for b in range(4) for c in range(4) if len({a, b, c}) == 3])
        return float(np.exp(q.log_probability(triplets)).sum())

    before = all_inlier_probability()
    for _ in range(150):
        log_p = torch.log_softmax(logits, 0)
        samples = WeightedSampler(log_p.detach().exp().double().numpy()).draw(4 * 2, rng)
        lp = ordered_triplet_log_prob(log_p, torch.from_numpy(samples)).view(4, 2).sum(1)
        losses = torch.tensor([0.0 if inlier[samples[2 * k : 2 * k + 2]].all(axis=1).any() else 1.0 for k in range(4)])
        objective = ((losses - losses.mean()) * lp).mean()
        opt.zero_grad()
        objective.backward()
        opt.step()
    after = all_inlier_probability()
    assert before == pytest.approx(4 * 3 * 2 / (12 * 11 * 10))
    assert after > 10 * before  # ~40x after 150 steps, for any sampler seed


def test_checkpoint_round_trip_and_layout_refusal(tmp_path):
    net = CorrespondenceNet(N_FEATURES, width=8, blocks=1)
    path = save_checkpoint(tmp_path / "a.pt", net, {"algo": "test"})
    loaded, payload = load_checkpoint(path)
    x, m = torch.randn(1, 20, N_FEATURES), torch.ones(1, 20, dtype=torch.bool)
    torch.testing.assert_close(loaded(x, m), net.eval()(x, m))
    assert payload["config"] == {"algo": "test"}
    obs = {"features": x[0].numpy(), "mask": np.ones(20, dtype=np.int8)}
    action = LearnedPolicy(loaded).act(obs)
    assert action.shape == (20,) and action.dtype == np.float32

    payload["feature_names"] = payload["feature_names"][::-1]
    torch.save(payload, tmp_path / "b.pt")
    with pytest.raises(ValueError, match="feature layout"):
        load_checkpoint(tmp_path / "b.pt")
    with pytest.raises(FileNotFoundError):
        load_checkpoint(tmp_path / "missing.pt")


def test_short_training_lowers_the_loss_on_fixed_seeds(tmp_path):
    from stereovo.simulation import simulate_frame

    def config(seed: int) -> NGRansacConfig:
        return NGRansacConfig(
            n_correspondences=150, epsilon_range=(0.75, 0.75), outlier_mix=(0.8, 0.2, 0.0), budget=6, pools=4,
            frames=100, learning_rate=1e-2, width=16, blocks=1, eval_every=50, eval_frames=10, frames_per_sequence=10,
            seed=seed, keep_best=False,
        )

    held_out = [simulate_frame(config(3).simulation(0.75), np.random.default_rng(1000 + i)) for i in range(20)]
    # One 100-frame run at this learning rate is chaotic (a change in the estimator's last digits
    # moves a seed's gain by 0.3), so the policy's gains are judged on average over three seeds.
    trainers = [NGRansacTrainer(config(seed)) for seed in (3, 4, 5)]
    mass_before = [_inlier_mass(trainer.net, held_out) for trainer in trainers]
    for trainer in trainers:
        trainer.train()
    mass_after = [_inlier_mass(trainer.net, held_out) for trainer in trainers]
    # The policy learns where to sample: more mass on inliers ...
    assert np.mean(mass_after) > np.mean(mass_before) + 0.1
    # ... and a lower pool loss late in training (each run's two 50-frame windows see different frames).
    histories = [trainer.history for trainer in trainers]
    assert np.mean([h[-1].mean_loss for h in histories]) < np.mean([h[0].mean_loss for h in histories]) - 0.2
    trainer = trainers[0]
    # Resuming restores the step count and weights.
    path = trainer.save(tmp_path / "ng.pt")
    resumed = NGRansacTrainer.resume(path)
    assert resumed.step == 100
    for a, b in zip(resumed.net.state_dict().values(), trainer.net.state_dict().values()):
        torch.testing.assert_close(a, b)


def test_entropy_bonus_keeps_the_sampling_distribution_spread_and_settings_are_validated():
    from stereovo.simulation import simulate_frame
    from vo_gym.features import compute_features

    def trained_entropy(weight: float, seed: int) -> float:
        config = NGRansacConfig(
            n_correspondences=100, epsilon_range=(0.6, 0.6), budget=4, pools=2, frames=30, learning_rate=3e-2,
            width=16, blocks=1, eval_every=1000, eval_frames=1, frames_per_sequence=10, seed=seed, keep_best=False,
            max_grad_norm=None, entropy_weight=weight,
        )
        trainer = NGRansacTrainer(config)
        trainer.train()
        frame = simulate_frame(config.simulation(0.6), np.random.default_rng(7))
        feats = compute_features(frame.prev, frame.curr, frame.scores, frame.camera, frame.noise_sigma)
        with torch.no_grad():
            log_p = torch.log_softmax(trainer.net(torch.from_numpy(feats)[None], torch.ones(1, frame.n, dtype=torch.bool))[0], 0)
        return float(-(log_p.exp() * log_p).sum())

    # The entropy's gradient vanishes at the near-uniform start, so the bonus shows only where
    # the policy gradient pulls towards a collapse, which some seeds do within 30 frames and
    # others not: compare means over three seeds.
    seeds = (5, 6, 7)
    spread = np.mean([trained_entropy(20.0, seed) for seed in seeds])
    plain = np.mean([trained_entropy(0.0, seed) for seed in seeds])
    assert spread > plain + 0.3
    assert spread > 0.9 * np.log(100)  # close to uniform over the 100 correspondences
    with pytest.raises(ValueError, match="entropy_weight"):
        NGRansacConfig(entropy_weight=-1.0)
    with pytest.raises(ValueError, match="max_grad_norm"):
        NGRansacConfig(max_grad_norm=0.0)
    # a network a checkpoint can hold: each size within 4096, the total within 2^24 parameters
    with pytest.raises(ValueError, match="blocks must be <= 4096, got 5000"):
        NGRansacConfig(blocks=5000)
    with pytest.raises(ValueError, match="width 2048 and blocks 2 make a network of 16,818,177 parameters"):
        NGRansacConfig(width=2048, blocks=2)


def test_smoothness_loss_prefers_the_motion_that_continues_the_previous_one():
    from agents.ngransac import inlier_loss, smooth_inlier_loss
    from stereovo.estimation import MotionEstimate
    from stereovo.simulation import SimulationConfig, simulate_frame

    frame = simulate_frame(SimulationConfig(n_correspondences=50), np.random.default_rng(0))
    inliers = np.zeros(50, dtype=bool)
    inliers[:20] = True

    def estimate(t):
        return MotionEstimate(np.eye(3), np.asarray(t, float), inliers, "ok", 16, 16, 800, 0.0, "msac")

    previous = (np.eye(3), np.array([0.0, 0.0, -1.0]))
    camera_like = smooth_inlier_loss(estimate([0.0, 0.0, -1.02]), frame, previous)
    object_like = smooth_inlier_loss(estimate([0.8, 0.0, -1.5]), frame, previous)
    assert inlier_loss(estimate([0.8, 0.0, -1.5]), frame) == pytest.approx(-0.4)
    assert object_like > camera_like + 0.3
    # Without a previous motion (first frame) it is the plain inlier loss.
    assert smooth_inlier_loss(estimate([0.8, 0.0, -1.5]), frame, None) == pytest.approx(-0.4)


def test_each_sequence_draws_its_own_process_and_the_seed_fixes_them():
    frames = first_frames(0)
    aucs = [f.score_auc for f in frames]
    assert len(set(aucs)) == len(aucs) and all(RANDOMISED_AUC[0] <= a <= RANDOMISED_AUC[1] for a in aucs)
    again = first_frames(0)
    for a, b in zip(frames, again):
        np.testing.assert_array_equal(a.prev, b.prev)
        assert a.score_auc == b.score_auc
    assert [f.score_auc for f in first_frames(1)] != aucs


def test_the_trainer_runs_on_the_randomised_stream():
    config = NGRansacConfig(domain_randomisation=True, frames=3, eval_every=3, eval_frames=2, n_correspondences=80,
                            frames_per_sequence=2, pools=2, budget=4)
    trainer = NGRansacTrainer(config)
    trainer.train()
    assert trainer.step == 3 and len(trainer.history) == 1


@pytest.mark.parametrize("keep_best", [True, False])
def test_training_ends_with_the_weights_of_the_best_evaluation_or_the_last_ones(keep_best):
    # Three steps, an evaluation after each (stubbed: scores 0.2, 0.6, 0.4 and the weights it saw): keep_best
    # (the default) ends with the second evaluation's weights, keep_best=False with the last step's.
    config = NGRansacConfig(n_correspondences=60, epsilon_range=(0.5, 0.5), budget=3, pools=2, frames=3, eval_every=1,
                            eval_frames=1, learning_rate=1e-2, width=8, blocks=1, entropy_weight=0.1, seed=1,
                            keep_best=keep_best)
    trainer = NGRansacTrainer(config)
    scores, seen = iter([0.2, 0.6, 0.4]), []

    def evaluate(n_frames):
        seen.append({k: v.detach().clone() for k, v in trainer.net.state_dict().items()})
        return next(scores)

    trainer.evaluate = evaluate
    net = trainer.train()
    assert len(seen) == 3 and [h.eval_success for h in trainer.history] == [0.2, 0.6, 0.4]
    assert trainer.best_eval == 0.6
    # every step moved the weights, so each evaluation saw its own
    for a, b in itertools.combinations(seen, 2):
        assert any(not torch.equal(a[k], b[k]) for k in a)
    expected = seen[1] if keep_best else seen[2]
    assert net is trainer.net
    state = net.state_dict()
    assert state.keys() == expected.keys()
    for k in expected:
        assert torch.equal(state[k], expected[k]), k


# --- The task losses by hand: inlier fraction, smoothness penalty, pose error in units of the success bounds ---


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


# --- One training step: its features, pools, losses, success and objective ---


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
    objective, losses, success, first = trainer.frame_loss(frame, previous)

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
    steps = [NGRansacTrainer(config).frame_loss(frame) for _ in range(2)]
    assert steps[0][1] == steps[1][1]
    assert float(steps[0][0].detach()) == float(steps[1][0].detach())


def test_frame_loss_success_is_strictly_under_the_bound(monkeypatch):
    # As frame_metrics' success: a pose error of exactly the bound (ratio 1) is a miss.
    config = NGRansacConfig(loss="self-supervised", n_correspondences=60, epsilon_range=(0.5, 0.5), budget=3, pools=2,
                            width=8, blocks=1, seed=4)
    frame = simulate_frame(config.simulation(0.5), np.random.default_rng(5))
    monkeypatch.setattr(ngransac, "pose_loss", lambda estimate, frame: 1.0)
    assert NGRansacTrainer(config).frame_loss(frame)[2] == [False, False]


# --- The draws' log-probability where float32 runs out of mass ---


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


@pytest.mark.parametrize("field, value, message", [
    ("frames", 10**400, "frames must be an integer >= 1 and <= 1000000000, got ~1e+400 (an integer of 401 digits)"),
    ("eval_every", 10**10, "eval_every must be an integer >= 1 and <= 1000000000, got 10000000000"),
    ("eval_frames", 0, "eval_frames must be an integer >= 1 and <= 1000000000, got 0"),
    ("budget", 10**10, "budget must be an integer >= 1 and <= 1000000000, got 10000000000"),
    ("frames_per_sequence", 10**7, "frames_per_sequence must be an integer >= 1 and <= 1000000, got 10000000"),
    ("learning_rate", -1.0, "learning_rate must be a finite number in (0, 0.1), got -1.0"),
    ("learning_rate", float("nan"), "learning_rate must be a finite number in (0, 0.1), got nan"),
    ("learning_rate", 1e30, "learning_rate must be a finite number in (0, 0.1), got 1e+30"),
])
def test_counts_past_their_cap_and_a_bad_learning_rate_are_refused_naming_the_field(field, value, message):
    with pytest.raises(ValueError) as err:
        NGRansacConfig(**{field: value})
    assert str(err.value) == message


def _tiny_checkpoint(path):
    config = NGRansacConfig(n_correspondences=60, budget=4, pools=2, frames=2, width=8, blocks=1, eval_every=2,
                            eval_frames=1, frames_per_sequence=3, learning_rate=2e-4)
    trainer = NGRansacTrainer(config)
    trainer.train()
    return trainer.save(path)


def test_resume_changes_only_the_fields_a_continuation_may_change(tmp_path):
    path = _tiny_checkpoint(tmp_path / "ng.pt")
    resumed = NGRansacTrainer.resume(path, frames=3, seed=7, eval_every=1)
    assert (resumed.config.frames, resumed.config.seed, resumed.config.eval_every) == (3, 7, 1)
    assert (resumed.config.budget, resumed.config.learning_rate, resumed.step) == (4, 2e-4, 2)
    resumed.train(frames=1)
    assert resumed.step == 3
    # the optimiser's state carries the learning rate, the network its sizes, the history its evaluations:
    # an override of such a field would be silently ignored, or change the run halfway, and is refused
    with pytest.raises(ValueError) as err:
        NGRansacTrainer.resume(path, learning_rate=0.5, budget=3, seed=1)
    assert str(err.value) == (f"NGRansacTrainer.resume: the checkpoint {path} fixes learning_rate=0.5, budget=3; "
                              "a resumed run changes only frames, seed, eval_every")
