"""The hostile outlier kinds of the simulator (stereovo.simulation.hostile) and the outliers preset."""

from __future__ import annotations

import numpy as np
import pytest

from stereovo.camera import StereoCamera
from stereovo.estimation.roles.solvers import fit_rigid
from stereovo.simulation import OUTLIER_KINDS, OUTLIER_PRESETS, OutlierKind, SimulationConfig, simulate_frame
from stereovo.simulation.hostile import duplicate_matches, student_t_scale


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


# --- the documented property of each hostile kind, checked on noise-free frames (sigma 0) against
# --- where the true motion puts each row's frame k-1 point.


def _points(meas: np.ndarray, cam: StereoCamera) -> np.ndarray:
    """Points ``(n, 3)`` of stereo rows ``(n, 4)`` of any positive disparity (no min_disparity)."""
    d = meas[:, 0] - meas[:, 2]
    z = cam.fx * cam.baseline / d
    return np.column_stack([(meas[:, 0] - cam.cx) / cam.fx * z, (meas[:, 1] - cam.cy) / cam.fy * z, z])


def _true_curr(frame, rows: np.ndarray) -> np.ndarray:
    """Where the true motion puts the frame k-1 points of ``rows`` (noise-free frames only)."""
    X = _points(frame.prev[rows], frame.camera)
    return frame.camera.project(X @ frame.truth.rotation.T + frame.truth.translation)


def _tau(frame) -> float:
    from stereovo.simulation.outliers import outlier_threshold

    return outlier_threshold(frame.noise_sigma)


def _px_distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.linalg.norm(a[:, :3] - b[:, :3], axis=1)


def _independent_frame():
    frame = _frame(outlier_mix={"independent": 1.0}, outlier_ratio=0.5, noise_sigma=0.0, seed=1)
    rows = np.flatnonzero(frame.truth.outlier_kind == OutlierKind.INDEPENDENT_MISMATCH)
    assert rows.size == 200
    return frame, rows


def test_independent_mismatches_stay_rectified():
    frame, rows = _independent_frame()
    # only uL and uR move independently: v moves alike in both images (a rectified pair)
    np.testing.assert_array_equal(frame.curr[rows, 1], frame.curr[rows, 3])
    assert np.any(frame.curr[rows, 1] != _true_curr(frame, rows)[:, 1])  # v did move


def test_independent_mismatches_are_detectable():
    frame, rows = _independent_frame()
    # every move that stayed within tau of the truth was redrawn: each row is a detectable outlier
    dist = _px_distance(frame.curr[rows], _true_curr(frame, rows))
    assert np.all(dist >= _tau(frame) - 1e-6)


def test_duplicate_matches_never_copy_a_row_onto_itself():
    # tau = 0 leaves no pair to redraw, so only the draw itself keeps a row from copying itself
    rng = np.random.default_rng(0)
    m = 5
    prev = np.arange(4 * m, dtype=float).reshape(m, 4)
    curr = prev + 1000.0
    src_prev, dup_curr = duplicate_matches(prev, curr, curr, 400, 0.0, rng)
    src = np.array([np.flatnonzero(np.all(prev == p, axis=1))[0] for p in src_prev])
    dst = np.array([np.flatnonzero(np.all(curr == c, axis=1))[0] for c in dup_curr])
    assert np.all(src != dst)
    assert set(dst.tolist()) == set(range(m))  # any other row can be the copied one


def test_duplicate_matches_redraw_a_copy_near_the_true_pixels():
    # rows 0 and 1 see (almost) the same frame-k pixels: copying one onto the other is no outlier
    rng = np.random.default_rng(0)
    true_curr = np.array([[100.0, 50.0, 90.0, 50.0], [101.0, 50.0, 91.0, 50.0],
                          [400.0, 200.0, 380.0, 200.0], [800.0, 100.0, 760.0, 100.0]])
    prev = true_curr - 5.0
    tau = 4.0
    src_prev, dup_curr = duplicate_matches(prev, true_curr, true_curr, 300, tau, rng)
    src = np.array([np.flatnonzero(np.all(prev == p, axis=1))[0] for p in src_prev])
    assert np.all(_px_distance(dup_curr, true_curr[src]) >= tau)
    assert np.any(src == 0) and np.any(src == 1)


def test_duplicate_matches_in_a_frame_are_detectable_outliers():
    frame = _frame(outlier_mix={"duplicate": 1.0}, outlier_ratio=0.5, noise_sigma=0.0, seed=2)
    dup = np.flatnonzero(frame.truth.outlier_kind == OutlierKind.DUPLICATE_MATCH)
    inl = np.flatnonzero(frame.truth.inlier)
    for row in dup:
        src = inl[np.all(frame.prev[inl] == frame.prev[row], axis=1)]
        dst = inl[np.all(frame.curr[inl] == frame.curr[row], axis=1)]
        assert src.size == 1 and dst.size == 1 and src[0] != dst[0]
    assert np.all(_px_distance(frame.curr[dup], _true_curr(frame, dup)) >= _tau(frame) - 1e-6)


def _far_frame():
    frame = _frame(outlier_mix={"far": 1.0}, outlier_ratio=0.5, noise_sigma=0.0, seed=4)
    cam = frame.camera
    rows = np.flatnonzero(frame.truth.outlier_kind == OutlierKind.FAR_CLUTTER)
    # rows that clipping touched (a right pixel left of the image at k-1, a pixel at a border at k)
    # are not where their depth puts them; the rest are
    inside = np.all((frame.prev[rows][:, 0::2] > 0) & (frame.curr[rows][:, 0::2] > 0)
                    & (frame.curr[rows][:, 0::2] < cam.width - 1) & (frame.curr[rows][:, 1::2] > 0)
                    & (frame.curr[rows][:, 1::2] < cam.height - 1), axis=1)
    assert inside.mean() > 0.8
    return frame, rows[inside]


def test_far_clutter_sits_far_away_and_drifts_from_its_static_point():
    frame, rows = _far_frame()
    tau = _tau(frame)
    assert np.all(_points(frame.prev[rows], frame.camera)[:, 2] > 300.0)  # hundreds of metres and more
    static = _true_curr(frame, rows)
    # the drift: 1-3 tau px in one image direction, the same in both images
    dist = _px_distance(frame.curr[rows], static)
    assert np.all(dist >= tau - 1e-6)
    assert np.all(dist <= 3 * np.sqrt(2) * tau + 1e-6)


def test_far_clutter_drifts_alike_in_both_images():
    frame, rows = _far_frame()
    static = _true_curr(frame, rows)
    shift = frame.curr[rows] - static
    # the same shift in both images: the disparity at k is the far point's, vL = vR
    np.testing.assert_allclose(shift[:, 2], shift[:, 0], atol=1e-6)
    np.testing.assert_allclose(shift[:, 3], shift[:, 1], atol=1e-6)
    assert np.all(_disparity(frame.curr[rows]) < 2.0)  # still no resolvable depth at k


def _repetitive_frame():
    frame = _frame(outlier_mix={"repetitive": 1.0}, outlier_ratio=0.5, noise_sigma=0.0, seed=3,
                   z_min=15.0, z_max=18.0)
    rows = np.flatnonzero(frame.truth.outlier_kind == OutlierKind.REPETITIVE_TEXTURE)
    return frame, rows


def test_repetitive_texture_sits_at_a_wrong_depth():
    frame, rows = _repetitive_frame()
    z_in = _points(frame.prev[frame.truth.inlier], frame.camera)[:, 2]
    assert np.all((z_in >= 15.0 - 1e-6) & (z_in <= 18.0 + 1e-6))  # the scene's depth range
    # the stereo match one period over: the depth at k-1 is the landmark's times or over 1.3-2,
    # outside the range every landmark lies in
    z = _points(frame.prev[rows], frame.camera)[:, 2]
    farther, nearer = z >= 1.3 * 15.0 - 1e-6, z <= 18.0 / 1.3 + 1e-6
    assert np.all(farther | nearer)
    assert farther.any() and nearer.any()  # each cluster nearer or farther at random: both occur


def test_repetitive_texture_clusters_hold_at_most_a_third_of_the_inliers():
    frame, rows = _repetitive_frame()
    cam = frame.camera
    n_in = int(frame.truth.inlier.sum())
    size = max(6, n_in // 3)
    assert rows.size > 2 * size
    curr = frame.curr[rows]
    unclipped = np.all((curr[:, 0::2] > 0) & (curr[:, 0::2] < cam.width - 1), axis=1)
    order = np.argsort(frame.prev[rows, 0], kind="stable")  # clusters are image strips
    order = order[unclipped[order]]
    X, Y = _points(frame.prev[rows], cam), _points(curr, cam)
    # no more than a third of the inliers follows one rigid motion: every strip one row longer
    # than a cluster mixes two motions
    for start in range(0, order.size - size, max(1, size // 4)):
        window = order[start : start + size + 1]
        R, t = fit_rigid(X[window], Y[window])
        fit = np.linalg.norm(Y[window] - (X[window] @ R.T + t), axis=1)
        assert np.max(fit) > 1e-3, start


def test_hostile_inlier_noise_is_student_t():
    from stereovo.simulation.pair import simulate_pair

    # no motion: an inlier's noise-free pixels are the same in both frames, so curr - prev is the
    # difference of two noise draws (sigma sqrt(2) for each of uL, v, uR)
    config = SimulationConfig(outliers="hostile", n_correspondences=3000, outlier_ratio=0.0, noise_sigma=0.5)
    pose = simulate_frame(config, 0).truth.pose_prev
    diffs = []
    for seed in range(4):
        frame = simulate_pair(config, pose, pose, 1, np.random.default_rng(seed))
        np.testing.assert_allclose(frame.truth.rotation, np.eye(3), atol=1e-12)
        inl = frame.truth.inlier
        diffs.append((frame.curr[inl] - frame.prev[inl])[:, :3].ravel() / (np.sqrt(2) * config.noise_sigma))
    e = np.concatenate(diffs)
    assert abs(e.std() - 1.0) < 0.15  # the noise keeps the sigma the estimator is told
    # heavy tails: the Gaussian puts 6e-5 of the coordinates beyond 4 sigma (about 2 of these 36000);
    # the difference of two unit-variance t(3) draws about 100 times as many
    assert np.mean(np.abs(e) > 4.0) > 30 * 6.3e-5
    kurtosis = np.mean(e**4) / np.mean(e**2) ** 2
    assert kurtosis > 5.0  # Gaussian: 3
