"""TUM / KITTI / CSV export: lossless round trips, format details, and agreement with evo."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from stereovo.geometry import make_transform, pose_update, so3_exp
from stereovo.io import read_kitti, read_tum, write_frame_csv, write_kitti, write_tum
from stereovo.metrics import ate


def random_trajectory(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    poses = [np.eye(4)]
    for _ in range(n - 1):
        R = so3_exp(rng.normal(0, 0.05, size=3))
        t = np.array([0.0, 0.0, -1.0]) + rng.normal(0, 0.1, size=3)
        poses.append(pose_update(poses[-1], R, t))
    return np.stack(poses)


def test_tum_round_trip_and_line_format(tmp_path):
    poses = random_trajectory(40)
    # A large (170 deg) rotation too, away from the identity-only comfort zone.
    poses[5] = make_transform(so3_exp(np.array([0.3, 2.9, -0.5])), [1.0, 2.0, 3.0])
    ts = np.linspace(0.0, 3.9, 40) + 1e9 / 3
    path = tmp_path / "sub" / "traj.tum"
    write_tum(path, poses, ts)
    lines = path.read_text().splitlines()
    assert len(lines) == 40
    for line in lines:
        assert "  " not in line and "\t" not in line and line == line.strip()
        assert len(line.split(" ")) == 8
    back, ts_back = read_tum(path)
    np.testing.assert_array_equal(ts_back, ts)
    np.testing.assert_allclose(back, poses, atol=1e-12, rtol=0)
    # Quaternion scalar part is written last and non-negative.
    qw = np.array([float(line.split()[7]) for line in lines])
    assert np.all(qw >= 0) and qw[0] == 1.0


def test_tum_round_trip_near_half_turn(tmp_path):
    # Within ~1e-7 rad of 180 deg, geometry.quaternion_from_rotation (via so3_log's
    # arccos) loses digits: the round trip holds to ~1e-8, not 1e-12.
    poses = np.stack([np.eye(4), make_transform(so3_exp(np.array([0.0, np.pi - 1e-7, 0.0])), [1.0, 2.0, 3.0])])
    write_tum(tmp_path / "pi.tum", poses)
    back, _ = read_tum(tmp_path / "pi.tum")
    np.testing.assert_allclose(back, poses, atol=1e-8, rtol=0)


def test_tum_default_timestamps_and_bad_shapes(tmp_path):
    poses = random_trajectory(5)
    write_tum(tmp_path / "a.tum", poses)
    _, ts = read_tum(tmp_path / "a.tum")
    np.testing.assert_array_equal(ts, np.arange(5.0))
    with pytest.raises(ValueError, match=r"timestamps must have shape \(5,\), got \(2,\)"):
        write_tum(tmp_path / "b.tum", poses, timestamps=[0.0, 1.0])
    with pytest.raises(ValueError, match=r"poses must have shape \(F, 4, 4\), got \(5, 3, 4\)"):
        write_tum(tmp_path / "c.tum", poses[:, :3, :])


def test_kitti_round_trip_and_format(tmp_path):
    poses = random_trajectory(30, seed=2)
    path = tmp_path / "traj.txt"
    write_kitti(path, poses)
    lines = path.read_text().splitlines()
    assert len(lines) == 30
    assert all(len(line.split(" ")) == 12 and "  " not in line for line in lines)
    # Row-major 3x4: entries 3, 7, 11 are the position.
    np.testing.assert_array_equal(np.array(lines[7].split(), float)[[3, 7, 11]], poses[7, :3, 3])
    np.testing.assert_array_equal(read_kitti(path), poses)  # repr floats are exact


def test_read_rejects_malformed(tmp_path):
    path = tmp_path / "bad.txt"
    path.write_text("# comment\n1 2 3\n")
    with pytest.raises(ValueError, match="expected 12"):
        read_kitti(path)


def test_frame_csv(tmp_path):
    rows = [
        {"frame": 1, "rot_err_deg": 0.1 + 0.2, "success": True, "status": "ok"},
        {"frame": 2, "rot_err_deg": float("nan"), "success": np.bool_(False), "status": "no consensus", "extra": 3},
    ]
    path = tmp_path / "frames.csv"
    write_frame_csv(path, rows)
    with path.open() as fh:
        read = list(csv.DictReader(fh))
    assert list(read[0]) == ["frame", "rot_err_deg", "success", "status", "extra"]
    assert float(read[0]["rot_err_deg"]) == 0.1 + 0.2  # full precision
    assert read[1]["rot_err_deg"] == "nan" and read[1]["success"] == "False" and read[0]["extra"] == ""


# ----------------------------------------------------------------------------- evo agreement


@pytest.mark.parametrize("align", [False, True])
def test_ate_agrees_with_evo_ape(tmp_path, align):
    file_interface = pytest.importorskip("evo.tools.file_interface")
    from evo.core import metrics as evo_metrics
    from evo.core import sync

    true = random_trajectory(60, seed=4)
    rng = np.random.default_rng(5)
    est = true.copy()
    est[:, :3, 3] += np.cumsum(rng.normal(0, 0.05, size=(60, 3)), axis=0)  # drift
    est = make_transform(so3_exp(np.array([0.0, 0.1, 0.0])), np.array([0.5, 0.0, 0.2])) @ est
    write_tum(tmp_path / "est.tum", est)
    write_tum(tmp_path / "true.tum", true)
    traj_est = file_interface.read_tum_trajectory_file(str(tmp_path / "est.tum"))
    traj_ref = file_interface.read_tum_trajectory_file(str(tmp_path / "true.tum"))
    traj_ref, traj_est = sync.associate_trajectories(traj_ref, traj_est)
    if align:
        traj_est.align(traj_ref, correct_scale=False)
    ape = evo_metrics.APE(evo_metrics.PoseRelation.translation_part)
    ape.process_data((traj_ref, traj_est))
    ours = ate(est, true, align=align)
    assert ape.get_statistic(evo_metrics.StatisticsType.rmse) == pytest.approx(ours, abs=1e-6)
    if align:
        assert ours < ate(est, true, align=False)
