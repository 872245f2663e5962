"""ARS (``ars``) and BaySAC's failure update, as a sampler of the shared loop."""

from __future__ import annotations

import numpy as np
import pytest

from stereovo.estimation.methods.ars import ArsSampler, baysac_failure_update


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
