"""SPRT / WaldSAC (Matas & Chum 2005; Chum & Matas 2008): the test's design, exact counts, the
adaptive epsilon and delta, and the stop summed over the history of tests.

Past 600 lines because one test is checked here in all its places: its design and counts against
values derived by hand, its verifier's compiled and numpy routes deciding alike point by point, and
the two recipes that run it (``waldsac``, ``probabilistic+sprt``)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from stereovo import estimate_motion
from stereovo.estimation.roles.scoring import ReprojectionResidual
from stereovo.estimation.methods.sprt import (
    SprtTermination,
    SprtTest,
    SprtVerification,
    good_model_exponent,
    sprt_design,
    rejection_probability,
)
from stereovo.estimation.roles.termination import all_inlier_probability
from stereovo.geometry import rotation_error
from stereovo.simulation import SimulationConfig, simulate_frame
from tests.support.verification import estimate, good_and_bad, setup, sprt_by_hand, succeeded


def reference_checks(sq_rows, samples, perm, threshold_sq, test: SprtTest):
    """Point-by-point SPRT on each hypothesis: the exact checks needed and whether it is rejected."""
    out = []
    for sq, sample in zip(sq_rows, samples):
        lam, checked = 1.0, 0
        for j in perm:
            if j in sample:
                continue
            checked += 1
            lam *= test.delta / test.epsilon if sq[j] < threshold_sq else (1 - test.delta) / (1 - test.epsilon)
            if lam > test.A:
                out.append((checked, True))
                break
        else:
            out.append((len(sq), False))
    return out


class SameResidualOtherModel(ReprojectionResidual):
    """The reprojection residual under another class: the verifiers' numpy route (the compiled one
    is chosen only for ReprojectionResidual itself)."""


def planar_pair(rng, n=120, collinear=False):
    """Points on the plane z = 12 m (or on one line in it), seen before and after a small motion."""
    if collinear:
        s = rng.uniform(-8, 8, n)
        X = np.c_[s, 0.3 * s + rng.normal(0, 1e-6, n), np.full(n, 12.0)]
    else:
        X = np.c_[rng.uniform(-8, 8, n), rng.uniform(-2, 2, n), np.full(n, 12.0)]
    from stereovo.geometry import se3_exp

    R, t = se3_exp(np.array([0.02, -0.01, 0.5, 0.01, 0.02, -0.005]))
    return frame_camera().project(X), frame_camera().project(X @ R.T + t)


def frame_camera():
    return simulate_frame(SimulationConfig(n_correspondences=20), 0).camera


def test_sprt_design_matches_the_reference_values():
    C, K, A = sprt_design(0.5, 0.05, t_m=20, m_s=1)
    assert C == pytest.approx(0.4946, abs=1e-4)
    assert A == pytest.approx(13.49, abs=0.01)
    assert A == pytest.approx(K + 1 + np.log(A), abs=1e-8)


def test_sprt_design_falls_back_to_full_verification():
    assert sprt_design(0.1, 0.1, 500)[2] == np.inf  # C = 0
    assert sprt_design(0.05, 0.1, 500)[2] == np.inf  # delta >= epsilon
    assert sprt_design(0.11, 0.1, 1.0)[2] == np.inf  # A < 2


def test_good_model_exponent():
    assert good_model_exponent(0.4, 0.4, 0.05) == 1.0
    for eps, eps_i, delta_i in ((0.5, 0.3, 0.05), (0.3, 0.5, 0.05), (0.6, 0.2, 0.01)):
        h = good_model_exponent(eps, eps_i, delta_i)
        assert h > 0
        value = eps * (delta_i / eps_i) ** h + (1 - eps) * ((1 - delta_i) / (1 - eps_i)) ** h
        assert value == pytest.approx(1.0, abs=1e-9)
    # A good model with fewer inliers than the design's delta drifts up: always rejected.
    assert good_model_exponent(0.04, 0.5, 0.05) == 0.0


def test_sprt_counts_exactly_the_checks_needed():
    frame, problem, ctx = setup()
    rng = np.random.default_rng(2)
    R_far, t_far = good_and_bad(frame, 6, 16, rng)
    R_near, t_near = good_and_bad(frame, 0, 10, rng, degrees=0.5, metres=0.05)  # partly consistent
    R, t = np.concatenate([R_far, R_near]), np.concatenate([t_far, t_near])
    samples = np.stack([rng.choice(problem.n, 3, replace=False) for _ in range(32)])
    verifier = SprtVerification(problem.n, t_m=500, epsilon0=0.4, delta0=0.05)
    test = verifier.current
    scores, checks = verifier.verify(ctx, R, t, np.random.default_rng(5), samples=samples)
    perm = np.random.default_rng(5).permutation(problem.n)  # the verifier's first draw
    expected = reference_checks(ctx.residuals(R, t), samples, perm, 9.0, test)
    assert checks == sum(c for c, _ in expected)
    np.testing.assert_array_equal(~np.isfinite(scores), [rejected for _, rejected in expected])
    assert np.all(np.isfinite(scores[:6]))  # the true motion passes
    assert not np.any(np.isfinite(scores[6:22]))  # far-off models are rejected early
    near_consistency = np.mean(ctx.residuals(R[22:], t[22:]) < 9.0, axis=1)
    assert np.any((near_consistency > 0.02) & ~np.isfinite(scores[22:]))  # mixed sequences were exercised
    # A model with no consistent point is rejected after exactly floor(log A / log((1-d)/(1-e))) + 1 checks.
    step = np.log((1 - test.delta) / (1 - test.epsilon))
    assert all(c == int(np.floor(np.log(test.A) / step)) + 1 for c, _ in expected[6:22])


def test_sprt_rejects_good_models_at_most_one_in_a():
    frame, problem, ctx = setup()
    consistent = ctx.residuals(frame.truth.rotation[None], frame.truth.translation[None])[0] < 9.0
    epsilon = consistent.mean()
    rng = np.random.default_rng(3)
    rejected = total = 0
    verifier = SprtVerification(problem.n, t_m=20, epsilon0=epsilon, delta0=0.05, delta_tolerance=np.inf)
    A = verifier.current.A
    R = np.repeat(frame.truth.rotation[None], 4, axis=0)
    t = np.repeat(frame.truth.translation[None], 4, axis=0)
    for _ in range(300):  # a fresh random order per batch: 1200 good models
        samples = np.stack([rng.choice(np.flatnonzero(consistent), 3, replace=False) for _ in range(4)])
        scores, _ = verifier.verify(ctx, R, t, rng, samples=samples)
        rejected += int(np.sum(~np.isfinite(scores)))
        total += 4
    assert verifier.current.A == A  # no redesign happened
    # Wald: P(reject a good model) <= 1/A; batches share an order, so allow generous slack.
    assert rejected / total <= 1.0 / A + 3 * np.sqrt(1.0 / A / 300)


def test_sprt_adapts_epsilon_and_delta_and_the_stop_uses_the_history():
    frame, problem, ctx = setup()
    verifier = SprtVerification(problem.n)
    stop = SprtTermination(verifier)
    assert verifier.current.epsilon == 0.1 and verifier.current.delta == 0.01
    inliers = np.zeros(problem.n, dtype=bool)
    inliers[:150] = True
    verifier.on_new_best(inliers, None)
    assert verifier.current.epsilon == 0.5 and len(verifier.history) == 2
    rng = np.random.default_rng(4)
    R, t = good_and_bad(frame, 0, 32, rng)
    samples = np.stack([rng.choice(problem.n, 3, replace=False) for _ in range(32)])
    verifier.verify(ctx, R, t, rng, samples=samples)
    assert len(verifier.history) == 3 and verifier.current.delta != 0.01  # delta re-estimated
    assert 1e-3 <= verifier.current.delta <= 0.3
    # With no draws yet, the stop is the bound with P_g (1 - 1/A) as the success chance per draw.
    current = verifier.current
    p = all_inlier_probability(150, problem.n) * (1 - 1 / current.A)
    assert stop.required(150, problem.n) == int(np.ceil(np.log(0.01) / np.log1p(-p)))
    # Draws made under earlier tests count towards the confidence.
    verifier.history[0].draws = 10
    verifier.history[1].draws = 10
    assert stop.required(150, problem.n) < 20 + int(np.ceil(np.log(0.01) / np.log1p(-p)))


def test_sprt_and_tdd_check_fewer_points_than_ransac_at_equal_success():
    config = SimulationConfig(n_correspondences=300, outlier_ratio=0.5)
    totals = {"ransac": 0, "r-ransac": 0, "waldsac": 0}
    for i in range(6):
        frame = simulate_frame(config, 200 + i)
        for method in totals:
            est = estimate(frame, method, i)
            assert succeeded(est, frame), (method, i)
            totals[method] += est.n_point_checks
    assert totals["waldsac"] < 0.6 * totals["ransac"], totals
    assert totals["r-ransac"] < 0.6 * totals["ransac"], totals


def test_compiled_sprt_decides_exactly_like_the_vectorised_test():
    import stereovo.estimation.methods.sprt as sprt_module

    frame, problem, ctx = setup()
    rng = np.random.default_rng(3)
    R, t = good_and_bad(frame, 5, 120, rng)
    samples = np.stack([rng.choice(problem.n, 3, replace=False) for _ in range(R.shape[0])])
    results = []
    original = sprt_module.ReprojectionResidual
    for compiled in (True, False):
        verifier = SprtVerification(problem.n, t_m=200.0, epsilon0=0.4, delta0=0.05)
        # the numpy route: make the compiled branch's type test fail for this call
        sprt_module.ReprojectionResidual = original if compiled else SameResidualOtherModel
        try:
            scores, checks = verifier.verify(ctx, R, t, np.random.default_rng(9), samples=samples)
        finally:
            sprt_module.ReprojectionResidual = original
        results.append((scores, checks, verifier.counters()["sprt_rejected"], verifier._ratio_sum))
    np.testing.assert_array_equal(results[0][0], results[1][0])
    assert results[0][1:3] == results[1][1:3]
    assert results[0][3] == pytest.approx(results[1][3])


@pytest.mark.parametrize("method", ["waldsac", "usac"])
@pytest.mark.parametrize("case", ["outlier-free", "identical", "coplanar", "near-collinear"])
def test_sprt_never_overflows(method, case):
    rng = np.random.default_rng(5)
    if case == "outlier-free":
        frame = simulate_frame(SimulationConfig(n_correspondences=400, outlier_ratio=0.0), 8)
        prev, curr, camera = frame.prev, frame.curr, frame.camera
    elif case == "identical":
        frame = simulate_frame(SimulationConfig(n_correspondences=400, outlier_ratio=0.0), 8)
        prev, curr, camera = frame.prev, frame.prev.copy(), frame.camera
    else:
        prev, curr = planar_pair(rng, collinear=case == "near-collinear")
        camera = frame_camera()
    with np.errstate(over="raise"):
        est = estimate_motion(prev, curr, camera, method=method, rng=0, noise_sigma=0.5)
    counters = est.report.counters
    assert np.isfinite(counters["sprt_epsilon"]) and np.isfinite(counters["sprt_delta"])
    if case == "near-collinear":  # every minimal sample degenerate: no hypothesis ever reaches the test
        assert est.status == "failed: all samples degenerate" and not est.ok and est.n_inliers == 0
        assert counters["sprt_tested"] == 0 and counters["sprt_designs"] == 1
        assert counters["sprt_epsilon"] == 0.1 and counters["sprt_delta"] == 0.01  # the defaults, untouched
        return
    assert est.status == "ok" and est.ok
    assert est.n_inliers >= 0.5 * prev.shape[0]
    # every hypothesis goes through the (active) test and ends rejected or accepted
    assert counters["sprt_tested"] == est.n_hypotheses > 0 and counters["sprt_full"] == 0
    assert counters["sprt_rejected"] + counters["sprt_accepted"] == counters["sprt_tested"]
    if case == "outlier-free":
        assert np.degrees(rotation_error(est.rotation, frame.truth.rotation)) < 1.0
        # the noisy minimal-sample models: some rejected, and each new best re-designs the test (epsilon = I / N)
        assert counters["sprt_rejected"] > 0 and counters["sprt_accepted"] > 0
        assert counters["sprt_designs"] > 1 and 0.1 < counters["sprt_epsilon"] < 1.0
    else:
        # noise-free pairs: every model is exact, every one accepted; its consensus is every row (epsilon 1,
        # not a test to design), so the first test stays
        assert est.n_inliers == prev.shape[0]
        assert counters["sprt_rejected"] == 0 and counters["sprt_accepted"] == counters["sprt_tested"]
        assert counters["sprt_designs"] == 1 and counters["sprt_epsilon"] == 0.1
    if case == "identical":
        assert np.degrees(rotation_error(est.rotation, np.eye(3))) < 0.05 and np.linalg.norm(est.translation) < 0.01


def test_good_model_exponent_is_finite_for_clean_frames():
    for epsilon, epsilon_i, delta_i in ((0.999999, 0.1, 0.01), (1 - 1e-12, 0.3, 0.001), (0.999, 0.9999, 0.3)):
        h = good_model_exponent(epsilon, epsilon_i, delta_i)
        assert np.isfinite(h) and h > 0, h
        a, b = delta_i / epsilon_i, (1 - delta_i) / (1 - epsilon_i)
        # h solves epsilon a^h + (1 - epsilon) b^h = 1
        assert np.logaddexp(np.log(epsilon) + h * np.log(a), np.log1p(-epsilon) + h * np.log(b)) == pytest.approx(
            0, abs=1e-9)


def test_waldsac_through_the_environment_on_an_outlier_free_episode():
    import gymnasium

    import vo_gym  # noqa: F401

    # a three-frame episode (n_frames=3, no time limit): the third step is the env's own end
    env = gymnasium.make("vo_gym/StereoVO-v0", n_frames=3, method="waldsac", outlier_ratio=0.0)
    assert env.spec.max_episode_steps is None
    assert env.unwrapped.sim_config.n_frames == 3 and env.unwrapped.method == "waldsac"
    env.reset(seed=0)
    env.action_space.seed(0)
    for step in range(1, 4):
        _, reward, terminated, truncated, info = env.step(env.action_space.sample())
        assert info["frame"] == step and info["outlier_ratio"] == 0.0
        assert info["success"] and info["status"] == "ok" and not info["fallback"], info
        assert info["rot_err_deg"] < 0.5 and info["trans_err_m"] < 0.05, info
        assert info["precision"] == 1.0 and info["n_inliers"] >= 400, info
        assert 0.0 < reward <= 1.0 and not terminated
        assert truncated == (step == 3) and ("trajectory" in info) == (step == 3)
    env.close()


# --- The SPRT's design, its exponent and its verifier, against values derived by hand ---


def _sprt_frame(n=200, epsilon=0.5, seed=11):
    from stereovo.estimation.problem import StereoProblem
    from stereovo.estimation.roles.scoring import InlierCount, ReprojectionResidual
    from stereovo.estimation.roles.verification import ScoringContext
    from stereovo.simulation import SimulationConfig, simulate_frame

    frame = simulate_frame(SimulationConfig(n_correspondences=n, outlier_ratio=epsilon), seed)
    problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
    return frame, problem, ScoringContext(problem, ReprojectionResidual(9.0), InlierCount(), 9.0)


class _OtherResidual:
    """Stands in for ReprojectionResidual in the sprt module's type test: the numpy route is taken."""


def test_sprt_design_by_hand():
    # epsilon 0.5, delta 0.05: C = 0.95 ln(0.95 / 0.5) + 0.05 ln(0.05 / 0.5) = 0.4946319;
    # t_M = 10: K = 4.946319; A solves A = K + 1 + ln A: A = 8.029433 (8.0294 - ln 8.0294 = 5.9463).
    C, K, A = sprt_design(0.5, 0.05, 10.0)
    assert C == pytest.approx(0.95 * math.log(1.9) + 0.05 * math.log(0.1), rel=1e-12)
    assert C == pytest.approx(0.4946319372, rel=1e-9)
    assert K == pytest.approx(4.946319372, rel=1e-9)
    assert A == pytest.approx(8.029433328, rel=1e-8)
    assert A - math.log(A) == pytest.approx(K + 1.0, rel=1e-9)
    # Two models per sample halve K.
    _, K2, A2 = sprt_design(0.5, 0.05, 10.0, m_s=2.0)
    assert K2 == pytest.approx(4.946319372 / 2, rel=1e-9)
    assert A2 - math.log(A2) == pytest.approx(K2 + 1.0, rel=1e-9)
    # The default initial design (0.1, 0.01) at t_M = 500: C = 0.0713312, K = 35.66561, A = 40.36354.
    C, K, A = sprt_design(0.1, 0.01, 500.0)
    assert (C, K, A) == pytest.approx((0.07133122708, 35.66561354, 40.36354045), rel=1e-8)


def test_sprt_design_switches_the_test_off():
    # t_M = 1 at (0.1, 0.01): K = 0.0713, A = 1.0713 + ln A has its fixed point near 1.5 < 2: off.
    C, K, A = sprt_design(0.1, 0.01, 1.0)
    assert C == pytest.approx(0.07133122708, rel=1e-8) and K == pytest.approx(0.07133122708, rel=1e-8)
    assert A == math.inf
    # delta >= epsilon: no test (K reported 0).
    C, K, A = sprt_design(0.3, 0.3, 500.0)
    assert (K, A) == (0.0, math.inf)
    # Probabilities outside (0, 1): (0, 0, inf).
    for epsilon, delta in ((0.0, 0.01), (1.0, 0.01), (0.5, 0.0), (0.5, 1.0)):
        assert sprt_design(epsilon, delta, 500.0) == (0.0, 0.0, math.inf)
    # A just above 2 is kept: t_M such that K + 1 + ln 2 = 2 gives A = 2; a little more stays finite.
    C = 0.95 * math.log(1.9) + 0.05 * math.log(0.1)
    t_m = (1.0 - math.log(2.0)) / C * 1.01
    assert 2.0 < sprt_design(0.5, 0.05, t_m)[2] < 2.1


def test_good_model_exponent_by_hand():
    # 0.7 (0.1/0.5)^h + 0.3 (0.9/0.5)^h = 1 at h = 2 (0.028 + 0.972).
    assert good_model_exponent(0.7, 0.5, 0.1) == pytest.approx(2.0, rel=1e-9)
    # 0.6 (0.2)^h + 0.4 (1.8)^h = 1: h = 1 gives 0.12 + 0.72 = 0.84 < 1, so h > 1, and h = 2 gives
    # 0.024 + 1.296 > 1, so 1 < h < 2.
    h = good_model_exponent(0.6, 0.5, 0.1)
    assert 1.0 < h < 2.0 and 0.6 * 0.2**h + 0.4 * 1.8**h == pytest.approx(1.0, abs=1e-9)
    assert good_model_exponent(0.5, 0.5, 0.1) == 1.0  # the design's own epsilon
    assert good_model_exponent(1.0, 0.5, 0.1) == math.inf  # every point consistent: never rejected
    assert good_model_exponent(0.0, 0.5, 0.1) == 0.0
    # A good model worse than the design drifts upwards (0.05 ln 0.2 + 0.95 ln 1.8 > 0): always rejected.
    assert good_model_exponent(0.05, 0.5, 0.1) == 0.0
    for eps_i, delta_i in ((0.0, 0.1), (1.0, 0.1), (0.5, 0.0), (0.5, 1.0)):
        assert good_model_exponent(0.7, eps_i, delta_i) == 0.0


def test_rejection_probability_is_a_to_the_minus_h():
    assert rejection_probability(4.0, 1.0) == pytest.approx(0.25, rel=1e-12)
    assert rejection_probability(9.0, 0.5) == pytest.approx(1 / 3, rel=1e-12)
    assert rejection_probability(3.0, 2.0) == pytest.approx(1 / 9, rel=1e-12)
    assert rejection_probability(math.inf, 1.0) == 0.0
    assert rejection_probability(4.0, math.inf) == 0.0
    assert rejection_probability(4.0, 0.0) == 1.0


@pytest.mark.parametrize(("option", "value"), [("t_m", 0.0), ("epsilon0", 1.0), ("epsilon0", 0.0), ("delta0", 0.0),
                                               ("delta0", 1.0), ("chunk", 1.5), ("chunk", 0)])
def test_sprt_options_are_validated_by_name(option, value):
    with pytest.raises(ValueError, match=rf"option sprt_{option} has an invalid value {value!r}"):
        SprtVerification(n=100, **{option: value})


def test_sprt_verifier_initial_design_and_new_bests():
    v = SprtVerification(n=100)
    c = v.counters()
    assert c["sprt_designs"] == 1 and c["sprt_epsilon"] == 0.1 and c["sprt_delta"] == 0.01
    assert c["sprt_A"] == pytest.approx(40.36354045, rel=1e-8)
    assert (c["sprt_tested"], c["sprt_rejected"], c["sprt_accepted"], c["sprt_full"]) == (0, 0, 0, 0)
    assert isinstance(v.chunk, int)
    # delta0 below the floor is clamped to 1e-3.
    assert SprtVerification(n=100, delta0=1e-5).delta == 1e-3
    assert SprtVerification(n=100, delta0=0.9).delta == 0.3
    mask = np.zeros(100, bool)
    mask[:30] = True
    v.on_new_best(mask, None)
    assert v.epsilon == 0.3 and len(v.history) == 2
    assert (v.current.epsilon, v.current.delta) == (0.3, 0.01)
    _, _, A = sprt_design(0.3, 0.01, 500.0)
    assert v.current.A == A
    v.on_new_best(mask, None)  # the same inlier ratio: no new test
    assert len(v.history) == 2
    v.on_new_best(np.ones(100, bool), None)  # epsilon = 1 is no design
    v.on_new_best(np.zeros(100, bool), None)
    assert len(v.history) == 2 and v.epsilon == 0.3


def test_good_model_exponent_beyond_the_bracket_is_its_end_not_an_error():
    # epsilon 0.9 against a test for epsilon_i 0.5 with delta_i just under it: log a = -log b = 2 x 10^-r
    # (nearly), so eps a^h + (1 - eps) b^h = 1 is 0.9 / y + 0.1 y = 1 with y = b^h: y = 9, h = ln 9 / (2 x 10^-r).
    # At r = 5 that is 1.1e5, found by the solver; at r = 6 it is 1.1e6, past the bracket's end (2^20 = 1.05e6),
    # which is returned: a good model is then never rejected (alpha = A^-h = 0) either way.
    assert good_model_exponent(0.9, 0.5, 0.5 - 1e-5) == pytest.approx(math.log(9) / 2e-5, rel=1e-4)
    h = good_model_exponent(0.9, 0.5, 0.5 - 1e-6)
    assert 1e6 <= h < math.log(9) / 2e-6
    assert rejection_probability(10.0, h) == 0.0


def test_sprt_verifier_with_its_test_off_scores_every_point_and_counts_each_batch():
    # delta0 >= epsilon0 switches the test off (A = inf): every hypothesis is scored on all N points (its
    # inlier count, the quality), accepted and counted as verified fully, batch after batch.
    from stereovo.geometry import random_rotation

    _, problem, ctx = _sprt_frame()
    rng = np.random.default_rng(2)
    R = np.stack([np.eye(3)] * 3 + [random_rotation(rng, 0.1) for _ in range(2)])
    t = np.array([[0.0, 0.0, -1.0], [0.0, 0.0, -0.9], [0.1, 0.0, -1.0], [0.0, 0.0, -1.0], [0.2, 0.1, -1.1]])
    samples = np.stack([rng.choice(problem.n, 3, replace=False) for _ in range(5)])
    verifier = SprtVerification(problem.n, epsilon0=0.1, delta0=0.2)
    assert not verifier.current.active
    counts = np.sum(ctx.residuals(R, t) < 9.0, axis=1)
    for batch in (1, 2):
        scores, checks = verifier.verify(ctx, R, t, rng, samples=samples)
        np.testing.assert_array_equal(scores, counts)
        assert checks == 5 * problem.n
        c = verifier.counters()
        assert (c["sprt_accepted"], c["sprt_full"], c["sprt_tested"]) == (5 * batch, 5 * batch, 0)


@pytest.mark.parametrize("route", ["compiled", "numpy"])
def test_sprt_verifier_decides_counts_and_reestimates_delta_point_by_point(monkeypatch, route):
    # Two batches of wrong motions near the truth, by hand: which are rejected, the point checks paid (a
    # rejected hypothesis the points up to its rejection, an accepted one all N), the accepted ones' scores,
    # and delta re-estimated as the mean over all rejected hypotheses so far of consistent / checked, a new
    # test designed when it moves by more than 5 %. Then a batch of the true motion, all accepted: no new
    # evidence, no new test, N checks each. Both routes: the compiled pass and the numpy one (chunks of 16,
    # 32, ... points: most of these hypotheses are rejected after the first chunk).
    import stereovo.estimation.methods.sprt as sprt_module
    from stereovo.geometry import random_rotation

    if route == "numpy":
        monkeypatch.setattr(sprt_module, "ReprojectionResidual", _OtherResidual)

    frame, problem, ctx = _sprt_frame()
    rng = np.random.default_rng(5)
    verifier = SprtVerification(problem.n, t_m=200.0, epsilon0=0.4, delta0=0.05)
    ratios, designs = [], 1
    for batch, seed in enumerate((1, 2)):
        R = np.stack([random_rotation(rng, np.radians(0.5)) @ frame.truth.rotation for _ in range(40)])
        t = frame.truth.translation + rng.normal(0, 0.05, (40, 3))
        samples = np.stack([rng.choice(problem.n, 3, replace=False) for _ in range(40)])
        test = verifier.current
        sq = ctx.residuals(R, t)
        log_consistent = math.log(test.delta / test.epsilon)
        log_inconsistent = math.log((1 - test.delta) / (1 - test.epsilon))
        perm = np.random.default_rng(seed).permutation(problem.n)
        accepted, checked, consistent = sprt_by_hand(sq, samples, perm, 9.0, log_consistent, log_inconsistent,
                                                     math.log(test.A))
        rejected = ~accepted
        assert 5 <= rejected.sum() <= 35
        scores, checks = verifier.verify(ctx, R, t, np.random.default_rng(seed), samples=samples)
        np.testing.assert_array_equal(np.isinf(scores), rejected)
        np.testing.assert_array_equal(scores[~rejected], np.sum(sq[~rejected] < 9.0, axis=1))
        assert checks == checked[rejected].sum() + (~rejected).sum() * problem.n
        # the accepted ones' inliers come from the residuals just computed; a rejected one's are computed
        i, j = np.flatnonzero(~rejected)[0], np.flatnonzero(rejected)[0]
        for k, fresh in ((i, False), (j, True)):
            mask, computed = ctx.inliers_of(R, t, k)
            np.testing.assert_array_equal(mask, sq[k] < 9.0)
            assert computed is fresh
        ratios += list(consistent[rejected] / checked[rejected])
        delta = min(max(np.mean(ratios), 1e-3), 0.3)
        c = verifier.counters()
        if abs(delta - test.delta) > 0.05 * test.delta:
            designs += 1
            assert c["sprt_delta"] == pytest.approx(delta, rel=1e-12)
        assert c["sprt_designs"] == designs and c["sprt_rejected"] == len(ratios)
        assert c["sprt_accepted"] == 40 * (batch + 1) - len(ratios)
    assert designs >= 2
    accepted = verifier.counters()["sprt_accepted"]
    assert accepted + len(ratios) == 80 and verifier.counters()["sprt_tested"] == 80
    good_R = np.repeat(frame.truth.rotation[None], 4, axis=0)
    good_t = np.repeat(frame.truth.translation[None], 4, axis=0)
    scores, checks = verifier.verify(ctx, good_R, good_t, np.random.default_rng(3), samples=samples[:4])
    assert np.all(np.isfinite(scores)) and checks == 4 * problem.n
    c = verifier.counters()
    assert c["sprt_designs"] == designs and c["sprt_rejected"] == len(ratios) and c["sprt_accepted"] == accepted + 4


def test_sprt_verifier_accepts_cheap_fits_and_single_point_chunks_and_designs_with_its_models_per_sample():
    # t_m in (0, 1] (a fit cheaper than a point check) and chunk = 1 are valid settings; m_s divides
    # K = t_m C / m_s, and A is the fixed point of A = K + 1 + log A.
    SprtVerification(50, t_m=0.5, chunk=1)
    epsilon, delta = 0.1, 0.01
    C = (1 - delta) * math.log((1 - delta) / (1 - epsilon)) + delta * math.log(delta / epsilon)
    for m_s in (1.0, 2.0):
        K = 500.0 * C / m_s
        A = K + 1.0
        for _ in range(200):
            A = K + 1.0 + math.log(A)
        assert SprtVerification(50, m_s=m_s).current.A == pytest.approx(A, rel=1e-9)


def test_sprt_verifier_hands_the_kernel_float64_motions_and_int64_samples():
    # kernels_verification takes float64 / int64 arrays, which its wrappers ensure: motions in half precision and
    # sample indices held as float16 (numba compiles no float16) or int32 give the verdicts, checks, scores and
    # delta of their float64 / int64 copies on the compiled route.
    from stereovo.geometry import random_rotation

    frame, problem, ctx = _sprt_frame()
    rng = np.random.default_rng(7)
    R = np.stack([random_rotation(rng, np.radians(0.5)) @ frame.truth.rotation for _ in range(30)]).astype(np.float16)
    t = (frame.truth.translation + rng.normal(0, 0.05, (30, 3))).astype(np.float16)
    samples = np.stack([rng.choice(problem.n, 3, replace=False) for _ in range(30)])

    def run(R, t, samples):
        verifier = SprtVerification(problem.n, t_m=200.0, epsilon0=0.4, delta0=0.05)
        scores, checks = verifier.verify(ctx, R, t, np.random.default_rng(3), samples=samples)
        return scores.tolist(), checks, verifier.delta, verifier.n_accepted

    expected = run(R.astype(float), t.astype(float), samples)
    assert 0 < expected[3] < 30
    assert run(R, t, samples) == expected
    assert run(R.astype(float), t.astype(float), samples.astype(np.float16)) == expected
    assert run(R.astype(float), t.astype(float), samples.astype(np.int32)) == expected


@pytest.mark.parametrize("method", ["waldsac", "probabilistic+sprt"])
def test_waldsac_method_options_reach_its_verifier(method):
    from stereovo.estimation.problem import StereoProblem
    from stereovo.estimation.registry import method_spec, validate_options

    frame = simulate_frame(SimulationConfig(n_correspondences=80, outlier_ratio=0.3), rng=2)
    problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
    given = {"sprt_t_m": 123.0, "sprt_epsilon0": 0.2, "sprt_delta0": 0.03, "sprt_chunk": 7}
    options, extra = validate_options(method, given)
    verifier = method_spec(method).build(problem, options, None, None, extra).verifier
    assert isinstance(verifier, SprtVerification) and verifier.n == problem.n
    assert (verifier.t_m, verifier.epsilon0, verifier.delta0, verifier.chunk) == (123.0, 0.2, 0.03, 7)
    default_options, default_extra = validate_options(method, {})
    defaults = method_spec(method).build(problem, default_options, None, None, default_extra).verifier
    assert (defaults.t_m, defaults.epsilon0, defaults.delta0, defaults.chunk) == (500.0, 0.1, 0.01, 16)
    with pytest.raises(ValueError, match="sprt_delta0"):
        estimate_motion(frame.prev, frame.curr, frame.camera, method=method, rng=0, sprt_delta0=1.5)


class _OtherMahalanobis:
    """Stands in for MahalanobisResidual in the sprt module's type test: the numpy route is taken."""


def _mahalanobis_batch(quality, n, epsilon, seed, n_good, n_bad, rng_seed):
    """probabilistic's 3-D Mahalanobis gate with ``quality`` on a simulated frame, and a batch of
    ``n_good`` true and ``n_bad`` wrong motions with a minimal sample each: ``(problem, ctx, R, t, samples)``."""
    from stereovo.estimation.problem import StereoProblem
    from stereovo.estimation.roles.scoring import CHI2_3_95, MahalanobisResidual
    from stereovo.estimation.roles.verification import ScoringContext

    frame = simulate_frame(SimulationConfig(n_correspondences=n, outlier_ratio=epsilon), seed)
    problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
    ctx = ScoringContext(problem, MahalanobisResidual(CHI2_3_95), quality, CHI2_3_95)
    rng = np.random.default_rng(rng_seed)
    R, t = good_and_bad(frame, n_good, n_bad, rng)
    samples = np.stack([rng.choice(problem.n, 3, replace=False) for _ in range(R.shape[0])])
    return problem, ctx, R, t, samples


def test_compiled_mahalanobis_sprt_decides_like_the_numpy_route(monkeypatch):
    # probabilistic's judge (the 3-D Mahalanobis gate, inlier count): the compiled pass and the chunked
    # numpy route reject the same hypotheses, pay the same checks and give the accepted ones the same scores.
    import stereovo.estimation.methods.sprt as sprt_module
    from stereovo.estimation.roles.scoring import CHI2_3_95, InlierCount

    problem, ctx, R, t, samples = _mahalanobis_batch(InlierCount(), 300, 0.6, 4, 5, 120, 3)
    results = []
    for route in ("compiled", "numpy"):
        if route == "numpy":
            monkeypatch.setattr(sprt_module, "MahalanobisResidual", _OtherMahalanobis)
        verifier = SprtVerification(problem.n, t_m=200.0, epsilon0=0.4, delta0=0.05)
        scores, checks = verifier.verify(ctx, R, t, np.random.default_rng(9), samples=samples)
        results.append((scores, checks, verifier.counters()["sprt_rejected"], verifier._ratio_sum))
    np.testing.assert_array_equal(results[0][0], results[1][0])
    assert results[0][1:3] == results[1][1:3]
    assert 0 < results[0][2] < R.shape[0]  # both outcomes exercised
    assert results[0][3] == pytest.approx(results[1][3])
    full = np.sum(ctx.residuals(R, t) < CHI2_3_95, axis=1)
    kept = np.isfinite(results[0][0])
    np.testing.assert_array_equal(results[0][0][kept], full[kept])


def test_probabilistic_sprt_succeeds_on_hostile_frames_with_a_fraction_of_the_checks():
    # The project's recipe with the SPRT: on hostile frames at eps 0.9 it finds the truth where
    # probabilistic does, checks a fraction of the points, and is deterministic per seed.
    config = SimulationConfig(n_correspondences=500, outlier_ratio=0.9, outliers="hostile")
    checks = {"probabilistic": 0, "probabilistic+sprt": 0}
    for i in range(4):
        frame = simulate_frame(config, 1000 + i)
        for method in checks:
            est = estimate(frame, method, i)
            assert succeeded(est, frame), (method, i)
            checks[method] += est.n_point_checks
        assert est.counters["sprt_tested"] > 0 and est.counters["sprt_rejected"] > 0
        again = estimate(frame, "probabilistic+sprt", i)
        np.testing.assert_array_equal(again.rotation, est.rotation)
        np.testing.assert_array_equal(again.inliers, est.inliers)
    assert checks["probabilistic+sprt"] < 0.3 * checks["probabilistic"], checks


def test_probabilistic_sprt_composes_its_sampler_verifier_and_stop():
    # The recipe's parts: the caller's priors or order reach the sampler, the SPRT verifier listens for
    # new bests, the SPRT stop reads the sampler's all-inlier chance (prior-aware), and a budget keeps
    # the fixed budget.
    from stereovo.estimation import method_spec
    from stereovo.estimation.problem import StereoProblem
    from stereovo.estimation.registry import split_options
    from stereovo.estimation.roles.samplers import ProsacSampler, UniformSampler, WeightedSampler
    from stereovo.estimation.roles.termination import FixedBudget

    frame = simulate_frame(SimulationConfig(n_correspondences=120, outlier_ratio=0.5), 3)
    problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
    spec = method_spec("probabilistic+sprt")
    shared, extra = split_options(spec, {})
    priors, order = np.where(frame.truth.inlier, 0.8, 0.2), np.argsort(-frame.scores)
    for given, kind in (((None, None), UniformSampler), ((priors, None), WeightedSampler), ((None, order), ProsacSampler)):
        c = spec.build(problem, shared, *given, extra)
        assert isinstance(c.sampler, kind)
        assert isinstance(c.verifier, SprtVerification) and c.verifier in c.listeners
        assert isinstance(c.termination, SprtTermination) and c.termination.probability.sampler is c.sampler
    budgeted, _ = split_options(spec, {"budget": 40})
    assert isinstance(spec.build(problem, budgeted, None, None, extra).termination, FixedBudget)
    est = estimate_motion(frame.prev, frame.curr, frame.camera, method="probabilistic+sprt", rng=0, budget=40)
    assert est.n_hypotheses == 40
    # the verifier heard the new bests: its last test is designed for a best model's inlier ratio
    est = estimate_motion(frame.prev, frame.curr, frame.camera, method="probabilistic+sprt", rng=0)
    assert est.counters["sprt_designs"] >= 2 and est.counters["sprt_epsilon"] != SprtVerification.epsilon0
    assert round(est.counters["sprt_epsilon"] * problem.n) == pytest.approx(est.counters["sprt_epsilon"] * problem.n)


class _LogLoss:
    """A quality that reads every residual exactly (no saturation at the gate)."""

    saturates = False

    def score(self, residual_sq, threshold_sq):
        return -np.sum(np.log1p(np.minimum(residual_sq, 1e12)), axis=1)


def test_compiled_mahalanobis_sprt_gives_exact_residuals_to_a_quality_that_does_not_saturate():
    # Capped at the gate only where the quality saturates there: a quality that reads every residual
    # gets the accepted hypotheses' scores of full scoring, bit for bit.
    problem, ctx, R, t, samples = _mahalanobis_batch(_LogLoss(), 200, 0.4, 6, 6, 60, 4)
    verifier = SprtVerification(problem.n, t_m=200.0, epsilon0=0.4, delta0=0.05)
    scores, _ = verifier.verify(ctx, R, t, np.random.default_rng(1), samples=samples)
    kept = np.isfinite(scores)
    assert 0 < np.count_nonzero(kept) < R.shape[0]
    np.testing.assert_array_equal(scores[kept], ctx.score(R[kept], t[kept]))
