"""``vo-gym`` commands wired to library code: in-frame samplers in ``vo --agent``, image sources in
``vo --source``, and ``train --algo adaptive``."""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from vo_gym_cli.main import main

ROOT = Path(__file__).resolve().parents[1]


def _one_line(capsys, command: str) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith(f"vo-gym {command}: error:") and "Traceback" not in err[0], err
    return err[0]


def _hypotheses(out: Path) -> list[int]:
    with (out / "frames.csv").open() as fh:
        return [int(float(r["n_hypotheses"])) for r in csv.DictReader(fh)]


def test_vo_runs_an_in_frame_sampler_by_name_and_by_path_as_the_estimator_api_does(tmp_path, capsys):
    from agents import LearnedEstimator
    from stereovo.simulation import Sequence, SimulationConfig

    argv = ["--method", "msac", "--frames", "4", "--n", "150", "--outliers", "0.8", "--seed", "2", "--no-progress"]
    assert main(["vo", "--agent", "adaptive-pg-prior", *argv, "--out", str(tmp_path / "name")]) == 0
    mine = tmp_path / "mine.pt"
    shutil.copy(ROOT / "agents" / "checkpoints" / "adaptive-pg-prior.pt", mine)
    assert main(["vo", "--agent", str(mine), *argv, "--out", str(tmp_path / "path")]) == 0
    summary = json.loads((tmp_path / "name" / "summary.json").read_text())
    assert summary["settings"]["agent"] == "adaptive-pg-prior" and summary["metrics"]["frames"] == 4
    assert summary["metrics"]["success_rate"] == 1.0
    by_name, by_path = _hypotheses(tmp_path / "name"), _hypotheses(tmp_path / "path")
    assert by_name == by_path

    # the command's estimates are LearnedEstimator's on the same frames and random stream
    sequence = Sequence(SimulationConfig(preset="car", n_frames=4, n_correspondences=150, outlier_ratio=0.8), seed=2)
    estimator = LearnedEstimator("adaptive-pg-prior", method="msac")
    rng = np.random.default_rng(2)
    direct = [estimator.estimate(f.prev, f.curr, f.camera, f.scores, rng=rng).n_hypotheses for f in sequence]
    assert by_name == direct and max(direct) <= 64
    est = np.loadtxt(tmp_path / "name" / "trajectory_est.kitti.txt")
    true = np.loadtxt(tmp_path / "name" / "trajectory_true.kitti.txt")
    assert est.shape == true.shape == (5, 12) and np.abs(est - true).max() < 0.05


def test_vo_in_frame_sampler_needs_a_sampling_method(tmp_path, capsys):
    assert main(["vo", "--agent", "adaptive-pg", "--method", "inlier-detection", "--frames", "2",
                 "--out", str(tmp_path / "v")]) == 2
    assert "does not sample" in _one_line(capsys, "vo")
    assert not (tmp_path / "v").exists()
