"""The hostile outlier kinds of the simulator (stereovo.simulation.hostile) and the outliers preset."""

from __future__ import annotations

import numpy as np
import pytest

from stereovo.camera import StereoCamera
from stereovo.estimation.roles.solvers import fit_rigid
from stereovo.simulation import OUTLIER_KINDS, OUTLIER_PRESETS, OutlierKind, SimulationConfig, simulate_frame
from stereovo.simulation.hostile import student_t_scale


def _frame(seed: int = 0, **kw):
    return simulate_frame(SimulationConfig(**{"n_correspondences": 400, "outlier_ratio": 0.6, **kw}), seed)


def _disparity(meas: np.ndarray) -> np.ndarray:
    return meas[:, 0] - meas[:, 2]


def test_default_preset_is_the_old_mix_and_gaussian():
    config = SimulationConfig()
    assert config.outlier_mix == (0.6, 0.2, 0.2)
    assert config.noise_dof is None
    assert SimulationConfig(outlier_mix=(0.6, 0.2, 0.2, 0.0, 0.0)).outlier_mix == (0.6, 0.2, 0.2)


def test_hostile_preset_counts_every_kind_it_names():
    frame = _frame(outliers="hostile")
    weights = SimulationConfig(outliers="hostile").outlier_weights
    n_out = int(round(0.6 * 400))
    counts = np.bincount(frame.truth.outlier_kind, minlength=len(OutlierKind))
    assert counts[OutlierKind.INLIER] == 400 - n_out
    for kind, label in zip(OUTLIER_KINDS, list(OutlierKind)[1:]):
        assert abs(counts[label] - weights[kind] * n_out) <= 1, kind
    assert counts[OutlierKind.MOVING_OBJECT] == 0
    assert SimulationConfig(outliers="hostile").noise_dof == OUTLIER_PRESETS["hostile"]["noise_dof"]


def test_independent_mismatches_reach_zero_or_negative_disparity():
    frame = _frame(outlier_mix={"independent": 1.0}, outlier_ratio=0.5)
    rows = frame.truth.outlier_kind == OutlierKind.INDEPENDENT_MISMATCH
    d = _disparity(frame.curr[rows])
    assert np.mean(d <= 2 * np.sqrt(2) * frame.noise_sigma) >= 0.03  # near zero or negative: what the default kinds never make
    inliers = frame.truth.inlier
    assert np.all(_disparity(frame.curr[inliers]) > frame.camera.min_disparity)
    # the left and right pixels moved apart: the disparity at k differs from the one at k-1 by a lot
    assert np.median(np.abs(d - _disparity(frame.prev[rows]))) > 2.0


def test_duplicate_matches_copy_an_inlier_row_exactly():
    frame = _frame(outlier_mix={"duplicate": 1.0}, outlier_ratio=0.3)
    dup = np.flatnonzero(frame.truth.outlier_kind == OutlierKind.DUPLICATE_MATCH)
    inl = np.flatnonzero(frame.truth.inlier)
    assert dup.size == int(round(0.3 * 400))
    for row in dup[:20]:
        same_prev = np.all(frame.prev[inl] == frame.prev[row], axis=1)
        same_curr = np.all(frame.curr[inl] == frame.curr[row], axis=1)
        assert same_prev.sum() == 1 and same_curr.sum() == 1
        assert np.flatnonzero(same_prev)[0] != np.flatnonzero(same_curr)[0]


def test_far_clutter_has_no_resolvable_depth_and_drifts():
    frame = _frame(outlier_mix={"far": 1.0}, outlier_ratio=0.3)
    rows = frame.truth.outlier_kind == OutlierKind.FAR_CLUTTER
    d = _disparity(frame.prev[rows])
    sigma_d = np.sqrt(2) * frame.noise_sigma
    assert np.median(d) < 2 * sigma_d  # below what the noise can resolve
    assert np.all(frame.prev[rows, 1] <= 0.5 * (frame.camera.height - 1) + 5 * frame.noise_sigma + 1e-9)


def test_repetitive_texture_clusters_follow_a_wrong_rigid_motion():
    cam = StereoCamera()
    frame = _frame(outlier_mix={"repetitive": 1.0}, outlier_ratio=0.3, noise_sigma=0.0, seed=3)
    rows = np.flatnonzero(frame.truth.outlier_kind == OutlierKind.REPETITIVE_TEXTURE)
    n_in = int(frame.truth.inlier.sum())
    size = max(6, n_in // 3)
    X, Y = cam.triangulate(frame.prev[rows]), cam.triangulate(frame.curr[rows])
    order = np.argsort(frame.prev[rows, 0], kind="stable")  # clusters are image strips
    wrong = 0
    for start in range(0, rows.size, size):
        cluster = order[start : start + size]
        if cluster.size < 3:
            continue
        inside = cluster[np.all((frame.curr[rows][cluster][:, 0::2] > 0) & (frame.curr[rows][cluster][:, 0::2] < cam.width - 1), axis=1)]
        assert inside.size >= 0.8 * cluster.size  # the shift goes towards the image centre: few rows clipped
        R, t = fit_rigid(X[inside], Y[inside])
        fit = np.linalg.norm(Y[inside] - (X[inside] @ R.T + t), axis=1)
        assert np.max(fit) < 1e-6 * np.max(X[inside][:, 2])  # one rigid motion explains the cluster exactly
        true_fit = np.linalg.norm(Y[cluster] - (X[cluster] @ frame.truth.rotation.T + frame.truth.translation), axis=1)
        wrong += np.median(true_fit) > 0.1
    assert wrong == -(-rows.size // size)  # and in every cluster that motion is not the true one


def test_student_t_noise_has_unit_variance_and_heavy_tails():
    z = np.random.default_rng(0).standard_normal(200_000)
    t = z * student_t_scale(3.0, z.shape, np.random.default_rng(1))
    assert abs(t.std() - 1.0) < 0.05
    assert np.mean(np.abs(t) > 3) > 3 * np.mean(np.abs(z) > 3)


def test_hostile_frames_are_deterministic_per_seed():
    a, b = _frame(5, outliers="hostile"), _frame(5, outliers="hostile")
    for name in ("prev", "curr", "scores"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    c = _frame(6, outliers="hostile")
    assert not np.array_equal(a.curr, c.curr)


@pytest.mark.parametrize(
    "kw,message",
    [
        (dict(outliers="nasty"), "SimulationConfig.outliers must be one of"),
        (dict(outlier_mix={"sky": 1.0}), r"unknown: \['sky'\]"),
        (dict(outlier_mix=(1.0, 0.0)), "SimulationConfig.outlier_mix must be 3 to 7"),
        (dict(outlier_mix=(0.0, 0.0, 0.0, 0.0)), "positive sum"),
        (dict(noise_dof=2.0), "SimulationConfig.noise_dof must be"),
    ],
)
def test_bad_outlier_settings_name_the_field(kw, message):
    with pytest.raises(ValueError, match=message):
        SimulationConfig(**kw)


def test_environment_takes_the_preset():
    import gymnasium as gym

    import vo_gym  # noqa: F401

    env = gym.make("vo_gym/StereoVO-v0", outliers="hostile", n_correspondences=100, n_frames=2)
    assert env.unwrapped.sim_config.outliers == "hostile"
    obs, _ = env.reset(seed=0)
    assert obs["features"].shape[0] == 100
    obs, reward, *_ = env.step(np.zeros(100, dtype=np.float32))
    assert np.isfinite(reward)
    env.close()
