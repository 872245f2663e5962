"""The ``vo-gym vo`` command end to end, and its argument validation."""

from __future__ import annotations

import argparse
import csv
import json

import numpy as np
import pytest

from stereovo.io import read_kitti, read_tum
from vo_gym_cli.main import main
from vo_gym_cli.commands.vo import parse_outliers

OUTPUTS = [
    "trajectory_est.tum", "trajectory_true.tum", "trajectory_est.kitti.txt",
    "trajectory_true.kitti.txt", "frames.csv", "odometry.png", "summary.json",
]


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("vo") / "run"
    argv = ["vo", "--frames", "10", "--n", "200", "--outliers", "0.3:0.6", "--seed", "3",
            "--out", str(out), "--no-progress"]
    return out, main(argv)


def test_tiny_run_writes_everything(tiny_run, capsys):
    out, code = tiny_run
    assert code == 0
    for name in OUTPUTS:
        assert (out / name).is_file() and (out / name).stat().st_size > 0, name
    with (out / "frames.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 10 and [int(r["frame"]) for r in rows] == list(range(1, 11))
    assert {"rot_err_deg", "trans_err_m", "success", "precision", "recall", "fallback"} <= set(rows[0])
    est, ts = read_tum(out / "trajectory_est.tum")
    true, _ = read_tum(out / "trajectory_true.tum")
    assert est.shape == true.shape == (11, 4, 4) and ts.tolist() == list(range(11))
    np.testing.assert_allclose(read_kitti(out / "trajectory_est.kitti.txt"), est, atol=1e-12)
    np.testing.assert_allclose(true[0], np.eye(4), atol=1e-15)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["settings"]["outliers"] == [0.3, 0.6]
    metrics = summary["metrics"]
    assert metrics["frames"] == 10 and metrics["method"] == "probabilistic"
    assert metrics["success_rate"] >= 0.8
    # 10 m is too short for KITTI segments: NaN becomes JSON null, never invalid JSON.
    assert metrics["kitti_segments"] == 0 and metrics["kitti_t_percent"] is None


def test_summary_table_states_units(tmp_path, capsys):
    assert main(["vo", "--frames", "3", "--n", "100", "--method", "msac", "--out", str(tmp_path), "--no-progress"]) == 0
    text = capsys.readouterr().out
    for needle in ("success rate", "deg", " m", "ms", "ATE", "RPE", "KITTI", "msac"):
        assert needle in text, needle


@pytest.mark.parametrize(
    "argv, needle",
    [
        (["--outliers", "1.5"], "outlier ratio 1.5"),
        (["--outliers", "0.9:0.3"], "lo <= hi"),
        (["--outliers", "half"], "not a number"),
        (["--frames", "0"], "--frames must be >= 1"),
        (["--method", "nonsense"], "invalid choice: 'nonsense'"),
        (["--preset", "boat"], "invalid choice: 'boat'"),
    ],
)
def test_bad_arguments_exit_nonzero_with_message(tmp_path, capsys, argv, needle):
    with pytest.raises(SystemExit) as exc:
        main(["vo", *argv, "--out", str(tmp_path / "x"), "--no-progress"])
    assert exc.value.code != 0
    assert needle in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


def test_config_error_is_reported_not_raised(tmp_path, capsys):
    # The AUC range is the simulator's rule: its ValueError becomes a message and exit code 2.
    code = main(["vo", "--auc", "0.3", "--frames", "2", "--out", str(tmp_path / "x"), "--no-progress"])
    assert code == 2
    err = capsys.readouterr().err
    assert "error: --auc must be a finite number in [0.5, 1), got 0.3" in err and "Traceback" not in err
    assert not (tmp_path / "x").exists()


def test_parse_outliers():
    assert parse_outliers("0.5") == 0.5
    assert parse_outliers("0") == 0.0
    assert parse_outliers("0.3:0.9") == (0.3, 0.9)
    for bad in ("1", "-0.1", "0.1:0.2:0.3", ":0.5", "0.5:1.0"):
        with pytest.raises(argparse.ArgumentTypeError):
            parse_outliers(bad)


def test_method_choices_follow_the_registry(capsys):
    from stereovo.estimation import available_methods

    with pytest.raises(SystemExit) as exc:
        main(["vo", "--help"])
    assert exc.value.code == 0
    text = capsys.readouterr().out
    assert all(name in text for name in available_methods())
