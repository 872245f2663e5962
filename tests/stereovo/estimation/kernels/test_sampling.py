"""The compiled sampling kernels (stereovo/estimation/kernels/sampling.py) against numpy formulations."""

import numpy as np


def test_compiled_weighted_draw_inverts_the_cut_cumulative_weights_like_searchsorted():
    """The compiled draw against the same inversion written with numpy's searchsorted."""
    from stereovo.estimation.kernels.sampling import weighted_triplets

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
        np.testing.assert_array_equal(suspect, expected)
