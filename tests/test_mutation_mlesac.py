"""MLESAC's inlier normaliser on covariances by hand, for the survivors of the mutmut run of
``stereovo/estimation/methods/mlesac.py`` (docs/mutation-testing.md): ``log((2 pi)^(-3/2) |S|^(-1/2))`` with
``S = S_X + S_Y``, slogdet's value kept bit for bit on well-conditioned rows, and eigenvalues floored
at ``COVARIANCE_FLOOR`` times the largest on numerically singular ones.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np

from stereovo.estimation.methods.mlesac import COVARIANCE_FLOOR, inlier_log_normaliser


def test_inlier_normaliser_keeps_slogdet_and_floors_only_ill_conditioned_rows():
    A = np.random.default_rng(3).normal(size=(20, 3, 3))
    spd = A @ np.swapaxes(A, 1, 2) + 0.5 * np.eye(3)
    rows = np.concatenate([np.stack([np.diag([1e-20, 1.0, 1.0]), np.diag([2e-12, 1.0, 4.0])]), spd])
    problem = SimpleNamespace(cov_prev=rows / 2, cov_curr=rows / 2)
    got = inlier_log_normaliser(problem)
    base = -1.5 * math.log(2 * math.pi)
    np.testing.assert_array_equal(got[2:], base - 0.5 * np.linalg.slogdet(spd)[1])  # bit for bit
    # eig 1e-20 < 1e-12 x 1: floored to 1e-12; eig 2e-12 < 1e-12 x 4: floored to 4e-12.
    assert abs(got[0] - (base - 0.5 * math.log(COVARIANCE_FLOOR * 1.0))) < 1e-12
    assert abs(got[1] - (base - 0.5 * (math.log(4e-12) + math.log(1.0) + math.log(4.0)))) < 1e-12
