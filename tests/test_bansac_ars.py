"""BANSAC and ARS as samplers of the shared loop; the loop's counters and feedback hook."""

from __future__ import annotations

import numpy as np
import pytest

from stereovo.estimation import EstimatorOptions, StereoProblem, estimate_motion, method_spec
from stereovo.estimation.ars import ArsSampler, baysac_failure_update
from stereovo.estimation.bansac import BansacSampler, BansacTermination, bansac_update
from stereovo.estimation.loop import RansacSearch, run_ransac
from stereovo.metrics import frame_metrics
from stereovo.simulation import SimulationConfig, simulate_frame


def test_bansac_update_matches_hand_computed_toy():
    # Four points; sample {0, 1, 2} with beliefs 0.5, 0.5, 0.8; the hypothesis calls 0, 1, 2, 3 inliers
    # except point 3 (out) and adds point 4 (in). delta = 0.5*0.5*0.8 = 0.2, r = 4/5 = 0.8, rho = 0.5.
    p = np.array([0.5, 0.5, 0.8, 0.6, 0.3])
    verdicts = np.array([True, True, True, False, True])
    out = bansac_update(p, np.array([0, 1, 2]), verdicts, recall=0.5)
    delta, r, rho = 0.2, 0.8, 0.5
    in_in, in_out = delta * rho + (1 - delta) * r, (1 - delta) * r  # 0.74, 0.64
    # point 3 called out: L_in = 1 - 0.74 = 0.26, L_out = 1 - 0.64 = 0.36
    expected3 = 0.6 * 0.26 / (0.6 * 0.26 + 0.4 * 0.36)
    # point 4 called in: L_in = 0.74, L_out = 0.64
    expected4 = 0.3 * 0.74 / (0.3 * 0.74 + 0.7 * 0.64)
    assert in_in == pytest.approx(0.74) and in_out == pytest.approx(0.64)
    assert out[3] == pytest.approx(expected3) == pytest.approx(0.52)
    assert out[4] == pytest.approx(expected4)
    np.testing.assert_array_equal(out[:3], p[:3])  # the sample's own points carry no evidence


def test_baysac_failure_update_matches_hand_computed_toy():
    p = np.array([0.5, 0.8, 0.9, 0.3])
    out = baysac_failure_update(p, np.array([0, 1, 2]))
    everyone = 0.5 * 0.8 * 0.9  # 0.36
    assert out[0] == pytest.approx(0.5 * (1 - 0.72) / (1 - everyone))  # 0.21875
    assert out[1] == pytest.approx(0.8 * (1 - 0.45) / (1 - everyone))
    assert out[2] == pytest.approx(0.9 * (1 - 0.40) / (1 - everyone))
    assert out[3] == 0.3


def test_ars_draws_the_most_probable_untried_sample():
    priors = np.array([0.1, 0.9, 0.2, 0.8, 0.7, 0.3, 0.05, 0.6, 0.4, 0.5])
    sampler = ArsSampler(10, priors)
    first = sampler.draw(1, np.random.default_rng(0))[0]
    assert sorted(first) == [1, 3, 4]
    second = sampler.draw(1, np.random.default_rng(0))[0]
    assert sorted(second) != [1, 3, 4]  # known to have failed, never drawn again while others remain


def test_bansac_stop_rule_reads_the_beliefs():
    sampler = BansacSampler(6, np.array([1.0, 1.0, 1.0, 0.1, 0.1, 0.1]), prior_ceiling=0.9)
    stop = BansacTermination(sampler, confidence=0.5, max_iterations=100)
    assert stop.required(0, 6) == 100  # nothing drawn yet
    sampler._history.append(np.array([[0, 1, 2]]))
    assert sampler.stop_confidence() == pytest.approx(0.9**3)
    assert stop.required(3, 6) == 0 and stop.counters() == {"bansac_stopped_by_rule": 1}


def _frames(eps: float, count: int, n: int = 300):
    return [simulate_frame(SimulationConfig(n_correspondences=n, outlier_ratio=eps), rng=s) for s in range(count)]


@pytest.mark.parametrize("method", ["bansac", "ars"])
def test_informative_priors_need_fewer_hypotheses_than_uniform_at_equal_success(method):
    success = {"prior": [], "uniform": []}
    hypotheses = {"prior": [], "uniform": []}
    for s, frame in enumerate(_frames(0.7, 10)):
        noise = np.random.default_rng(100 + s).normal(0, 0.3, frame.n)
        priors = np.where(frame.truth.inlier, 0.9, 0.05) * np.exp(noise)
        for key, kwargs in (("prior", {"method": method, "priors": priors}),
                            ("uniform", {"method": "probabilistic", "local_refit": True})):
            est = estimate_motion(frame.prev, frame.curr, frame.camera, rng=s, **kwargs)
            success[key].append(frame_metrics(est, frame.truth).success)
            hypotheses[key].append(est.n_hypotheses)
    # equal success within one frame of ten: a belief-driven search can lock onto a partial consensus
    # (a minimal stereo fit finds only part of its inliers), which a uniform search of ~50 never does
    assert np.mean(success["uniform"]) == 1.0 and np.mean(success["prior"]) >= 0.9
    assert np.mean(hypotheses["prior"]) < 0.5 * np.mean(hypotheses["uniform"])


@pytest.mark.parametrize("method", ["bansac", "ars"])
def test_methods_run_without_priors_same_seed_same_result_and_refuse_an_order(method):
    frame = _frames(0.5, 1)[0]
    a = estimate_motion(frame.prev, frame.curr, frame.camera, method=method, rng=3)
    b = estimate_motion(frame.prev, frame.curr, frame.camera, method=method, rng=3)
    assert a.ok and frame_metrics(a, frame.truth).success
    np.testing.assert_array_equal(a.rotation, b.rotation)
    assert a.n_hypotheses == b.n_hypotheses and a.report.counters == b.report.counters
    assert any(key.startswith(method) for key in a.report.counters)
    with pytest.raises(ValueError, match="not an order"):
        estimate_motion(frame.prev, frame.curr, frame.camera, method=method, order=np.arange(frame.n))
    with pytest.raises(ValueError, match="initial_probability"):
        estimate_motion(frame.prev, frame.curr, frame.camera, method=method, initial_probability=1.5)


class _CountingSampler:
    """A uniform sampler that records what the feedback hook shows it."""

    def __init__(self, inner):
        self.inner, self.n, self.seen = inner, inner.n, []

    def draw(self, batch, rng):
        return self.inner.draw(batch, rng)

    def on_hypotheses(self, R, t, inlier_masks, residual_sq, state):
        self.seen.append((R.shape[0], inlier_masks.shape, residual_sq.shape, state.samples.shape, state.n_hypotheses))

    def counters(self):
        return {"batches_seen": len(self.seen)}


def test_feedback_hook_sees_every_verified_batch_and_counters_are_merged():
    frame = _frames(0.5, 1)[0]
    problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, 0.5)
    options = EstimatorOptions(budget=12, batch_size=4)
    components = method_spec("msac").build(problem, options, None, None, {})
    plain = run_ransac(problem, components, np.random.default_rng(0))
    components = method_spec("msac").build(problem, options, None, None, {})
    components.sampler = _CountingSampler(components.sampler)
    search = RansacSearch(problem, components, np.random.default_rng(0))
    while not search.done:
        search.step()
    hooked = search.finish()
    np.testing.assert_array_equal(plain.rotation, hooked.rotation)  # the hook changes no draw
    seen = components.sampler.seen
    assert [s[4] for s in seen] == [4, 8, 12]
    assert all(s[1] == (s[0], problem.n) and s[2] == (s[0], problem.n) and s[3] == (s[0], 3) for s in seen)
    assert hooked.counters == {"batches_seen": 3}
    # the hook's residuals are counted: full residuals of every scored hypothesis once more
    assert hooked.n_point_checks == plain.n_point_checks + hooked.n_scored * problem.n
