"""The match-score model (stereovo.simulation.scores): calibrated inlier probabilities, and
Guided-MLESAC fed with them as its gamma_i (Tordoff & Murray's priors are probabilities)."""

import numpy as np
import pytest
from scipy.stats import binom

from stereovo import estimate_motion
from stereovo.benchmark import METHOD_INPUTS, ClassicalEstimator, score_inputs
from stereovo.metrics import frame_metrics
from stereovo.simulation import SimulationConfig, simulate_frame
from stereovo.simulation.scores import draw_scores, score_inlier_probability


def pooled(auc: float, eps: float, frames: int = 40):
    scores, inlier = [], []
    for seed in range(frames):
        f = simulate_frame(SimulationConfig(n_correspondences=500, outlier_ratio=eps, score_auc=auc), 700 + seed)
        scores.append(f.scores)
        inlier.append(f.truth.inlier)
    return np.concatenate(scores), np.concatenate(inlier)


@pytest.mark.parametrize("auc,eps", [(0.9, 0.5), (0.75, 0.5), (0.9, 0.8)])
def test_probabilities_are_calibrated(auc, eps):
    """Among matches given probability about p, a fraction p are inliers (20 000 matches in ten bins
    of equal count, each bin's inlier count within its binomial 99.9 % range) when the prior inlier
    share is the frame's; the raw score is not calibrated."""
    scores, inlier = pooled(auc, eps)
    p = score_inlier_probability(scores, auc, inlier_share=1 - eps)
    bins = np.array_split(np.argsort(p), 10)
    for rows in bins:
        expected = float(np.mean(p[rows]))
        hits = int(np.count_nonzero(inlier[rows]))
        low, high = binom.ppf(0.0005, rows.size, expected), binom.ppf(0.9995, rows.size, expected)
        assert low <= hits <= high, (auc, eps, expected, hits / rows.size)
    # a raw score is not a probability: some decile of raw scores is off by more than 0.2
    gaps = [abs(np.mean(scores[rows]) - np.mean(inlier[rows])) for rows in np.array_split(np.argsort(scores), 10)]
    assert max(gaps) > 0.2, gaps


def test_frame_probabilities_are_the_posterior_at_an_uninformed_share():
    frame = simulate_frame(SimulationConfig(n_correspondences=300, outlier_ratio=0.6, score_auc=0.9), 5)
    p = frame.match_probabilities
    assert frame.score_auc == 0.9
    np.testing.assert_array_equal(p, score_inlier_probability(frame.scores, 0.9, 0.5))
    order = np.argsort(frame.scores)
    assert np.all(np.diff(p[order]) >= 0) and np.all((p > 0) & (p < 1))  # monotone, never certain
    # at AUC 0.5 the score says nothing: every match keeps the prior share
    np.testing.assert_allclose(score_inlier_probability(frame.scores, 0.5, 0.3), 0.3, rtol=1e-12)
    # the extreme scores the model can draw stay finite in log-odds
    edges = score_inlier_probability(np.array([0.0, np.finfo(float).tiny, 1 - 2**-53, 1.0]), 0.95)
    assert np.all(np.isfinite(edges)) and edges[0] < 1e-20 and edges[-1] > 1 - 1e-6


def test_draw_scores_has_the_stated_auc():
    rng = np.random.default_rng(0)
    inlier = rng.random(20_000) < 0.3
    for auc in (0.6, 0.75, 0.9):
        s = draw_scores(inlier, auc, np.random.default_rng(1))
        ins, outs = np.sort(s[inlier]), s[~inlier]
        below = np.searchsorted(ins, outs).sum() / (ins.size * outs.size)  # P(inlier score < outlier score)
        assert 1 - below == pytest.approx(auc, abs=0.01)


@pytest.mark.parametrize("kwargs,message", [
    ({"auc": 1.0}, "auc must be a finite number in [0.5, 1), got 1.0"),
    ({"auc": 0.4}, "auc must be a finite number in [0.5, 1), got 0.4"),
    ({"auc": 0.9, "inlier_share": 0.0}, "inlier_share must be a finite number in (0, 1), got 0.0"),
    ({"auc": 0.9, "inlier_share": float("nan")}, "inlier_share must be a finite number in (0, 1), got nan"),
])
def test_bad_settings_are_named(kwargs, message):
    with pytest.raises(ValueError) as err:
        score_inlier_probability(np.array([0.2, 0.7]), **kwargs)
    assert str(err.value) == message


@pytest.mark.parametrize("scores,got", [(np.array([0.2, 1.5]), "got 1.5 at row 1"), (np.array([np.nan, 0.2]), "got nan at row 0"),
                                        (np.array([0.2, -0.0, -1e-300]), "got -1e-300 at row 2"),
                                        (np.ones((2, 2)) * 0.5, "got shape (2, 2)")])
def test_bad_scores_are_named(scores, got):
    with pytest.raises(ValueError) as err:
        score_inlier_probability(scores, 0.9)
    assert str(err.value) == f"scores must be a 1-D array of numbers in [0, 1], {got}"


def test_benchmark_hands_guided_mlesac_the_probabilities():
    frame = simulate_frame(SimulationConfig(n_correspondences=100, outlier_ratio=0.5, score_auc=0.9), 2)
    assert METHOD_INPUTS["guided-mlesac"] == "probabilities"
    np.testing.assert_array_equal(score_inputs(frame, "probabilities")["priors"], frame.match_probabilities)
    direct = estimate_motion(frame.prev, frame.curr, frame.camera, method="guided-mlesac",
                             priors=frame.match_probabilities, noise_sigma=frame.noise_sigma, rng=3)
    for inputs in ("probabilities", None):  # None: asked for priors, it is retried with its declared form
        via = ClassicalEstimator("guided-mlesac", inputs)(frame, np.random.default_rng(3))
        np.testing.assert_array_equal(via.inliers, direct.inliers)
        assert via.n_hypotheses == direct.n_hypotheses


def test_guided_mlesac_with_calibrated_priors_halves_mlesac_hypotheses():
    """eps 0.8, AUC 0.9, N 200 (20 seeded frames): with the calibrated gamma_i guided-MLESAC draws at
    most half of MLESAC's mean hypotheses at no less success, and fewer than with the raw scores,
    whose near-certain values (three in ten inliers score above 0.99) distort the mixture likelihood."""
    runs = {"mlesac": [], "raw": [], "calibrated": []}
    for seed in range(20):
        f = simulate_frame(SimulationConfig(n_correspondences=200, outlier_ratio=0.8, score_auc=0.9), 300 + seed)
        for name, kw in (("mlesac", {"method": "mlesac"}),
                         ("raw", {"method": "guided-mlesac", "priors": f.scores}),
                         ("calibrated", {"method": "guided-mlesac", "priors": f.match_probabilities})):
            est = estimate_motion(f.prev, f.curr, f.camera, rng=seed, noise_sigma=f.noise_sigma, **kw)
            runs[name].append((est.n_hypotheses, frame_metrics(est, f.truth).success))
    hyps = {k: np.mean([h for h, _ in v]) for k, v in runs.items()}
    success = {k: np.mean([s for _, s in v]) for k, v in runs.items()}
    assert hyps["calibrated"] <= 0.5 * hyps["mlesac"], hyps
    assert hyps["calibrated"] < hyps["raw"], hyps
    assert success["calibrated"] >= success["mlesac"], success


@pytest.mark.parametrize("auc", [0.5, 0.75, 0.95, 0.9999999])
def test_draw_scores_is_the_clipped_probit_formulation(auc):
    """The drawn scores are np.clip(ndtr(normal + shift * inlier), tiny, 1 - ulp), bit for bit, every call."""
    from scipy.special import ndtr

    from stereovo.simulation.scores import latent_shift

    lowest, highest = np.finfo(float).tiny, np.nextafter(1.0, 0.0)
    for seed in range(5):
        inlier = np.random.default_rng(seed).random(800) < 0.5
        ours = draw_scores(inlier, auc, np.random.default_rng(seed))
        reference_rng = np.random.default_rng(seed)
        expected = np.clip(ndtr(reference_rng.standard_normal(800) + latent_shift(auc) * inlier), lowest, highest)
        assert ours.tobytes() == expected.tobytes()
    with pytest.raises(ValueError, match=r"auc must be a finite number in \[0\.5, 1\), got 1\.0"):
        draw_scores(inlier, 1.0, np.random.default_rng(0))  # an AUC of 1 is refused, also after valid ones


@pytest.mark.parametrize("auc", [0.5, 0.75, 0.9999999])
def test_draw_scores_of_read_only_and_other_labels_is_the_formulation(auc):
    from scipy.special import ndtr

    from stereovo.simulation.scores import latent_shift

    lowest, highest = np.finfo(float).tiny, np.nextafter(1.0, 0.0)
    for seed in range(5):
        inlier = np.random.default_rng(seed).random(600) < 0.3
        expected = np.clip(ndtr(np.random.default_rng(seed).standard_normal(600) + latent_shift(auc) * inlier),
                           lowest, highest)
        frozen = inlier.copy()
        frozen.flags.writeable = False  # the simulator's cached labels
        for labels in (frozen, inlier.astype(np.int8), inlier.tolist()):
            labels_array = np.asarray(labels)
            assert draw_scores(labels_array, auc, np.random.default_rng(seed)).tobytes() == expected.tobytes()
