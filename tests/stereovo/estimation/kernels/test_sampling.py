"""The compiled sampling kernels (stereovo/estimation/kernels/sampling.py) against numpy formulations."""

import numpy as np


def test_compiled_weighted_draw_inverts_the_cut_cumulative_weights_like_searchsorted():
    """The compiled draw against the same inversion written with numpy's searchsorted."""
    from stereovo.estimation.kernels.sampling import CANCELLATION, weighted_triplets

    rng = np.random.default_rng(2)
    for trial in range(60):
        n = int(rng.integers(3, 400))
        priors = rng.random(n) if trial % 3 else np.exp(8.0 * rng.normal(size=n))
        priors[rng.random(n) < 0.3 * (trial % 2)] = 0.0
        priors[:3] += 1.0
        w = priors / priors.sum()
        cdf = np.cumsum(w)
        before = np.concatenate([[0.0], cdf[:-1]])
        total = cdf[-1]
        u = rng.random((256, 3))

        def invert(mass):
            return np.minimum(np.searchsorted(cdf, mass, side="right"), n - 1)

        a = invert(u[:, 0] * total)
        x = u[:, 1] * (total - w[a])
        b = invert(np.where(x < before[a], x, x + w[a]))
        lo, hi = np.minimum(a, b), np.maximum(a, b)
        x = u[:, 2] * (total - w[a] - w[b])
        x = np.where(x < before[lo], x, x + w[lo])
        c = invert(np.where(x < before[hi], x, x + w[hi]))
        samples, suspect = weighted_triplets(u, w, cdf, before)
        np.testing.assert_array_equal(samples, np.stack([a, b, c], axis=1))
        expected = (b == a) | (c == a) | (c == b) | (w[a] == 0) | (w[b] == 0) | (w[c] == 0)
        # and a mass left that the cumulative sums cannot resolve (one or two weights hold almost all)
        expected |= (total - w[a] < CANCELLATION * total) | (total - w[a] - w[b] < CANCELLATION * total)
        np.testing.assert_array_equal(suspect, expected)


def _tables_by_numpy(priors):
    """The guided sampler's tables as numpy built them: normalised weights, cumsum, shifted cumsum."""
    from stereovo.estimation.roles.samplers import normalised_weights

    w = normalised_weights(priors)
    positive = w[w > 0]
    cdf = np.cumsum(w)
    return w, cdf, np.concatenate([[0.0], cdf[:-1]]), bool(np.all(positive == positive[0])), int(positive.size)


def _prior_sets(rng):
    n = 517  # past numpy's pairwise block of 128, not a multiple of 8
    yield rng.random(n)
    yield rng.exponential(1.0, n) * (rng.random(n) < 0.3)  # many zeros
    yield np.full(n, 0.25)  # equal weights
    yield np.where(rng.random(n) < 0.5, 2.0, 0.0)  # equal positive weights among zeros
    yield np.exp(rng.normal(0.0, 30.0, n))  # a wide range of scales
    yield rng.random(5)
    yield np.array([0.0, 1e-310, 1.0, 3.0])  # a quotient below the smallest normal: the careful path
    yield np.full(40, 1e307)  # the sum overflows: the careful path
    yield np.full(9, 5e-324)  # the sum is subnormal: the careful path
    yield rng.integers(0, 4, n).astype(float)


def test_cumulative_weights_are_numpys_tables_or_decline():
    from stereovo.estimation.kernels.sampling import cumulative_weights
    from stereovo.estimation.roles.samplers import WeightedSampler

    rng = np.random.default_rng(8)
    declined = 0
    for priors in _prior_sets(rng):
        w, cdf, before, equal, n_positive, direct = cumulative_weights(priors, np.finfo(float).tiny)
        expected = _tables_by_numpy(priors)
        sampler = WeightedSampler(priors)
        for got, want in zip((sampler.weights, sampler._cdf, sampler._before), expected[:3]):
            np.testing.assert_array_equal(got, want)
        assert (sampler._equal_weights, sampler._n_positive) == expected[3:]
        if direct:
            for got, want in zip((w, cdf, before), expected[:3]):
                np.testing.assert_array_equal(got, want)
            assert (equal, n_positive) == expected[3:]
        else:
            declined += 1
    assert declined == 3  # the three careful cases, and only those
