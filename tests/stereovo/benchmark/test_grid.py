"""stereovo.benchmark.grid: the default and full grids, trials, validation, and frames that depend
on the seed, the cell and the repeat only."""

from __future__ import annotations

import numpy as np
import pytest

from stereovo import benchmark as bm
from stereovo.benchmark import GridCell, Trial
from stereovo.simulation import OutlierKind, SimulationConfig
from tests.support.benchmark import TINY


def test_default_grid_is_small_and_has_two_ns():
    g = bm.DEFAULT_GRID
    assert len(g.ns) >= 2 and len(g.epsilons) >= 3 and max(g.epsilons) >= bm.HEAVY_EPSILON
    assert g.max_iterations == bm.DEFAULT_MAX_ITERATIONS
    assert g.n_trials == len(g.trials()) <= 120


def test_full_grid_has_every_epsilon_noise_auc_n_and_outlier_kind():
    g = bm.FULL_GRID
    assert g.epsilons == pytest.approx(tuple(np.round(np.arange(0.1, 0.95, 0.1), 1)))
    assert g.noise_sigmas == (0.25, 0.5, 1.0, 2.0) and g.score_aucs == (0.5, 0.75, 0.9)
    assert g.ns == (100, 500, 1000) and set(g.outlier_kinds) == set(bm.OUTLIER_MIXES) - {"hostile"}
    assert g.n_cells == 9 * 4 * 3 * 3 * 4 == len(g.cells())


def test_trials_enumerate_cells_and_repeats():
    trials = TINY.trials()
    assert [t.index for t in trials] == list(range(4))
    assert [(t.cell_index, t.repeat) for t in trials] == [(0, 0), (0, 1), (1, 0), (1, 1)]
    assert [t.cell.epsilon for t in trials] == [0.2, 0.2, 0.5, 0.5]


@pytest.mark.parametrize(
    "change, needle",
    [
        ({"epsilons": ()}, "epsilons must not be empty"),
        ({"ns": (100, 100)}, "repeated"),
        ({"outlier_kinds": ("aliens",)}, "unknown outlier kind"),
        ({"epsilons": (1.2,)}, "outlier_ratio"),
        ({"score_aucs": (0.3,)}, "score_auc"),
        ({"noise_sigmas": (0.0,)}, "noise_sigmas"),
        ({"frames_per_cell": 0}, "frames_per_cell"),
        ({"max_iterations": 0}, "max_iterations"),
    ],
)
def test_grid_validation(change, needle):
    with pytest.raises(ValueError, match=needle):
        TINY.with_axes(**change)


def test_outlier_kinds_reach_the_simulator():
    for kind, mix in bm.OUTLIER_MIXES.items():
        config = GridCell(0.5, 0.5, 0.75, 100, kind).config()
        if mix is None:  # the hostile preset: its mix and its Student-t noise
            hostile = SimulationConfig(outliers="hostile")
            assert config.outliers == "hostile"
            assert (config.outlier_mix, config.noise_dof) == (hostile.outlier_mix, hostile.noise_dof) != (
                SimulationConfig().outlier_mix, None)
        else:
            assert (config.outlier_mix, config.outliers, config.noise_dof) == (mix, "default", None)
    frame = bm.simulate_trial(Trial(0, 0, GridCell(0.5, 0.5, 0.75, 100, "stereo"), 0), seed=0)
    assert set(np.unique(frame.truth.outlier_kind)) == {0, 2}
    frame = bm.simulate_trial(Trial(0, 0, GridCell(0.5, 0.5, 0.75, 200, "hostile"), 0), seed=0)
    assert {OutlierKind.INDEPENDENT_MISMATCH, OutlierKind.DUPLICATE_MATCH, OutlierKind.FAR_CLUTTER,
            OutlierKind.REPETITIVE_TEXTURE} <= set(np.unique(frame.truth.outlier_kind))
    assert OutlierKind.MOVING_OBJECT not in frame.truth.outlier_kind


def test_frames_depend_on_seed_cell_and_repeat_only():
    cell = GridCell(0.5, 0.5, 0.75, 80)
    a = bm.simulate_trial(Trial(0, 0, cell, 0), seed=3)
    again = bm.simulate_trial(Trial(7, 5, cell, 0), seed=3)  # position in the grid does not matter
    np.testing.assert_array_equal(a.prev, again.prev)
    np.testing.assert_array_equal(a.scores, again.scores)
    other_repeat = bm.simulate_trial(Trial(0, 0, cell, 1), seed=3)
    other_seed = bm.simulate_trial(Trial(0, 0, cell, 0), seed=4)
    assert not np.array_equal(a.prev, other_repeat.prev)
    assert not np.array_equal(a.prev, other_seed.prev)


def test_noise_and_auc_axes_share_geometry():
    base = bm.simulate_trial(Trial(0, 0, GridCell(0.5, 0.5, 0.75, 80), 0), seed=0)
    noisier = bm.simulate_trial(Trial(0, 0, GridCell(0.5, 1.0, 0.75, 80), 0), seed=0)
    sharper = bm.simulate_trial(Trial(0, 0, GridCell(0.5, 0.5, 0.9, 80), 0), seed=0)
    np.testing.assert_array_equal(base.truth.rotation, noisier.truth.rotation)
    np.testing.assert_array_equal(base.truth.inlier, noisier.truth.inlier)
    assert not np.array_equal(base.prev, noisier.prev)
    np.testing.assert_array_equal(base.prev, sharper.prev)
    assert not np.array_equal(base.scores, sharper.scores)


def test_estimator_seeds_differ_by_name_and_reject_bad_seeds():
    cell = GridCell(0.5, 0.5, 0.75, 80)
    a = np.random.default_rng(bm.estimator_seed(0, cell, 0, "ransac")).random()
    b = np.random.default_rng(bm.estimator_seed(0, cell, 0, "msac")).random()
    assert a != b and a == np.random.default_rng(bm.estimator_seed(0, cell, 0, "ransac")).random()
    assert a != np.random.default_rng(bm.estimator_seed(0, cell, 1, "ransac")).random()  # each repeat its own stream
    for bad in (-1, 1.5, True):
        with pytest.raises(ValueError, match="seed"):
            bm.frame_seed(bad, cell, 0)
