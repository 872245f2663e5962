"""Fixtures of the trials tests."""

from __future__ import annotations

import pytest

import stereovo.benchmark as bm
from tests.support.trials import GRID, trial_estimators


@pytest.fixture(scope="module")
def reference():
    """The grid's rows in this process (one local worker)."""
    return bm.run_benchmark(GRID.trials(), trial_estimators(), seed=5, workers=1, progress=False)
