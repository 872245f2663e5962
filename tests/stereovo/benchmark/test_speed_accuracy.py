"""The speed-accuracy sweep and the score-quality table on a few tiny frames: every estimator's
points, the figure, the presets, and the table's layout (no timing is asserted)."""

from __future__ import annotations

import numpy as np
import pytest

from stereovo.benchmark import peers
from stereovo.benchmark import speed_accuracy as sa
from stereovo.simulation import OUTLIER_KINDS


def test_sweep_gives_a_point_per_estimator_and_setting_and_draws_the_figure(tmp_path):
    points = sa.sweep(120, [0.5], "random", frames=2, confidences=(0.9, 0.99), repeats=2)
    names = set(sa.curve_runners(0.99))
    assert {(p.estimator, p.setting) for p in points} == {(n, c) for n in names for c in (0.9, 0.99)}
    ours = [p for p in points if p.estimator.startswith("ours")]
    assert all(p.success == 1.0 and p.median_rot_deg < 0.2 and p.median_hypotheses >= 1 for p in ours)
    assert all(p.frames == 2 and p.median_ms > 0 for p in points)
    path = sa.plot_curves(points, tmp_path / "curves.png", "test")
    assert path.stat().st_size > 10_000


def test_cells_are_the_same_frames_for_every_estimator_and_presets_are_checked():
    a = sa.cell_frames(sa.simulation_config(80, 0.5, "default"), 2, 0)
    b = sa.cell_frames(sa.simulation_config(80, 0.5, "default"), 2, 0)
    assert all(np.array_equal(x.prev, y.prev) and np.array_equal(x.curr, y.curr) for x, y in zip(a, b))
    random = sa.simulation_config(80, 0.5, "random")
    assert random.outlier_mix == sa.RANDOM_MIX
    with pytest.raises(ValueError, match="preset must be one of .* got 'nasty'"):
        sa.simulation_config(80, 0.5, "nasty")
    hostile = sa.simulation_config(80, 0.5, "hostile")
    assert hostile.outliers == "hostile" and hostile.outlier_ratio == 0.5
    assert hostile.n_correspondences == 80 and hostile.noise_sigma == 0.5
    # the simulator's hostile preset: its mix over the outlier kinds and its heavy-tailed noise
    kinds = dict(zip(OUTLIER_KINDS, hostile.outlier_mix))
    assert kinds == {"random": 0.3, "stereo": 0.05, "moving": 0.0, "independent": 0.3, "duplicate": 0.1, "far": 0.15,
                     "repetitive": 0.1}
    assert hostile.noise_dof == 3.0
    default = sa.simulation_config(80, 0.5, "default")
    assert default.outliers == "default" and default.outlier_mix == (0.6, 0.2, 0.2) and default.noise_dof is None


def test_prior_table_rows_and_markdown():
    rows = sa.prior_table(120, [0.5], [0.9], "random", frames=2)
    assert {r["estimator"] for r in rows} == set(sa.prior_runners())
    assert all(r["auc"] == 0.9 and r["epsilon"] == 0.5 for r in rows)
    table = sa.prior_table_markdown(rows).splitlines()
    assert len(table) == 2 + len(rows)
    own = [line for line in table if "ours, uniform" in line]
    assert own and own[0].split("|")[6].strip() == "1.00"  # its time over its own uniform time


def test_the_cpu_clock_can_be_chosen_and_is_checked():
    try:
        peers.set_clock("cpu")
        frame = sa.cell_frames(sa.simulation_config(80, 0.3, "random"), 1, 0)[0]
        assert peers.ours()(frame, 0).seconds > 0
    finally:
        peers.set_clock("wall")
    with pytest.raises(ValueError, match="clock must be one of .* got 'gpu'"):
        peers.set_clock("gpu")
