"""Helpers for the trials tests: a tiny grid, its estimators, journals."""

from __future__ import annotations

from pathlib import Path

from stereovo import benchmark as bm
from stereovo.trials import TrialJournal


GRID = bm.BenchmarkGrid(epsilons=(0.2, 0.6), noise_sigmas=(0.5,), score_aucs=(0.9,), ns=(60,), frames_per_cell=3,
                        max_iterations=200)
METHODS = ("ransac", "msac")


def trial_estimators():
    return bm.classical_estimators(list(METHODS), max_iterations=GRID.max_iterations)


def open_journal(folder: Path) -> TrialJournal:
    return TrialJournal(folder, bm.TRIAL_COLUMNS, bm.parse_trial_value)
