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


# ---------------------------------------------------------------- vo --source

OUTPUTS = ["trajectory_est.tum", "trajectory_true.tum", "trajectory_est.kitti.txt", "trajectory_true.kitti.txt",
           "frames.csv", "covariances.npy", "odometry.png", "summary.json"]


@pytest.fixture(scope="module")
def short():
    from images_support import rendered

    sequence = rendered(preset="car", n_frames=3, resolution="vga", seed=4)
    yield sequence
    sequence.close()


def test_vo_on_a_rendered_source_writes_trajectory_drift_and_plot(tmp_path, capsys, short):
    from stereovo.io import read_tum

    out = tmp_path / "r"
    assert main(["vo", "--source", "rendered", "--resolution", "vga", "--frames", "3", "--seed", "4",
                 "--no-progress", "--out", str(out)]) == 0
    for name in OUTPUTS:
        assert (out / name).is_file() and (out / name).stat().st_size > 0, name
    summary = json.loads((out / "summary.json").read_text())
    assert summary["settings"]["source"] == "rendered" and summary["settings"]["resolution"] == "vga"
    assert summary["metrics"]["frames"] == 3 and summary["metrics"]["success_rate"] == 1.0
    assert "kitti_t_percent" in summary["metrics"]
    true, _ = read_tum(out / "trajectory_true.tum")
    assert np.allclose(true, short.true_poses, atol=1e-6)  # the rendered sequence of that seed
    est, _ = read_tum(out / "trajectory_est.tum")
    assert np.abs(est[:, :3, 3] - true[:, :3, 3]).max() < 0.05
    assert "rendered, 3 frames" in capsys.readouterr().out


def test_vo_on_a_kitti_folder_with_and_without_poses(tmp_path, capsys, short):
    from images_support import write_kitti

    write_kitti(tmp_path / "data", short, "05")
    out = tmp_path / "k"
    # --frames 2 takes the first 2 of the 3 pairs
    assert main(["vo", "--source", f"kitti:{tmp_path / 'data'}:05", "--frames", "2", "--no-progress",
                 "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["metrics"]["frames"] == 2 and summary["metrics"]["success_rate"] == 1.0
    est = np.loadtxt(out / "trajectory_est.kitti.txt")
    true = np.loadtxt(out / "trajectory_true.kitti.txt")
    assert est.shape == true.shape == (3, 12) and np.abs(est - true).max() < 0.05

    write_kitti(tmp_path / "bare", short, "00", with_poses=False)
    out = tmp_path / "b"
    assert main(["vo", "--source", f"kitti:{tmp_path / 'bare'}", "--method", "msac", "--no-progress",
                 "--out", str(out)]) == 0
    assert not (out / "trajectory_true.tum").exists()
    for name in ("trajectory_est.tum", "trajectory_est.kitti.txt", "frames.csv", "odometry.png", "summary.json"):
        assert (out / name).is_file(), name
    summary = json.loads((out / "summary.json").read_text())
    assert summary["metrics"]["frames"] == 3 and summary["metrics"]["kitti_t_percent"] is None
    with (out / "frames.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 3 and all(int(r["n_inliers"]) > 0 for r in rows)
    assert "no ground-truth poses" in capsys.readouterr().out


@pytest.mark.parametrize("source, needle", [
    ("bogus", "--source must be one of rendered, rendered:PRESET, kitti:PATH, kitti:PATH:SEQ, got 'bogus'"),
    ("rendered:plane", "--source 'rendered:plane': the rendered preset must be one of car, free, got 'plane'"),
])
def test_bad_source_strings_are_one_line_and_write_nothing(tmp_path, capsys, source, needle):
    with pytest.raises(SystemExit) as exc:
        main(["vo", "--source", source, "--out", str(tmp_path / "v")])
    assert exc.value.code == 2
    assert needle in _one_line(capsys, "vo")
    assert not (tmp_path / "v").exists()


def test_a_missing_kitti_folder_is_one_line_naming_source(tmp_path, capsys):
    pytest.importorskip("cv2")
    assert main(["vo", "--source", f"kitti:{tmp_path / 'none'}", "--out", str(tmp_path / "v")]) == 2
    line = _one_line(capsys, "vo")
    assert "--source kitti:" in line and "no folder" in line
    assert not (tmp_path / "v").exists()


@pytest.mark.parametrize("missing, source, extra", [("moderngl", "rendered", "render"),
                                                    ("cv2", "rendered", "images"),
                                                    ("cv2", "kitti:/data", "images")])
def test_a_missing_extra_is_one_line_naming_it(tmp_path, capsys, monkeypatch, missing, source, extra):
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == missing else real(name, *a))
    assert main(["vo", "--source", source, "--out", str(tmp_path / "v")]) == 2
    line = _one_line(capsys, "vo")
    assert f"'{extra}' extra ({missing} is not installed): pip install 'vo-gym[{extra}]'" in line
    assert not (tmp_path / "v").exists()


# ---------------------------------------------------------------- train --algo adaptive

def test_train_adaptive_within_a_time_budget_writes_a_usable_in_frame_sampler(tmp_path, capsys):
    torch = pytest.importorskip("torch")
    from agents import LearnedEstimator
    from agents.adaptive import load_adaptive
    from stereovo.simulation import SimulationConfig, simulate_frame

    out = tmp_path / "ad"
    threads = torch.get_num_threads()
    try:
        assert main(["train", "--algo", "adaptive", "--minutes", "0.5", "--clock", "cpu", "--max-episodes", "2",
                     "--frames-per-episode", "2", "--n-correspondences", "60", "--seed", "3", "--no-progress",
                     "--out", str(out)]) == 0
    finally:
        torch.set_num_threads(threads)
    summary = json.loads((out / "training.json").read_text())
    assert summary["algo"] == "adaptive" and summary["episodes"] == 2 and summary["frames"] == 4
    assert summary["config"]["minutes"] == 0.5 and summary["config"]["clock"] == "cpu"
    assert summary["config"]["seed"] == 3 and summary["config"]["n"] == 60
    _, payload = load_adaptive(out / "adaptive.pt")
    assert payload["config"]["max_episodes"] == 2
    assert f"checkpoint: {out / 'adaptive.pt'}" in capsys.readouterr().out
    frame = simulate_frame(SimulationConfig(n_correspondences=60, outlier_ratio=0.3), rng=1)
    est = LearnedEstimator(out / "adaptive.pt", budget=8).estimate(frame.prev, frame.curr, frame.camera, frame.scores)
    assert est.sampler_kind == "in-frame" and est.n_hypotheses == 8


@pytest.mark.parametrize("argv, needle", [
    (["--prior", "nope"], "--prior 'nope' is not a shipped one-shot sampler; shipped: ngransac-supervised"),
    (["--resume", str(ROOT / "agents" / "checkpoints" / "ppo.pt")], "a one-shot checkpoint; --algo adaptive"),
    (["--prior", "ppo", "--resume", str(ROOT / "agents" / "checkpoints" / "adaptive-pg.pt")], "--prior starts a fresh network, --resume continues"),
])
def test_train_adaptive_errors_are_one_line(tmp_path, capsys, argv, needle):
    pytest.importorskip("torch")
    assert main(["train", "--algo", "adaptive", "--minutes", "0.01", *argv, "--out", str(tmp_path / "t")]) == 2
    assert needle in _one_line(capsys, "train")
    assert not (tmp_path / "t" / "adaptive.pt").exists()


def test_train_adaptive_minutes_must_be_positive(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["train", "--algo", "adaptive", "--minutes", "0", "--out", str(tmp_path / "t")])
    assert exc.value.code == 2
    assert "--minutes must be > 0.0" in _one_line(capsys, "train")


# ---------------------------------------------------------------- evaluate --source rendered

def test_evaluate_on_rendered_images_replays_the_same_frames_to_every_agent(tmp_path, capsys, short):
    argv = ["evaluate", "--source", "rendered", "--resolution", "vga", "--episodes", "1", "--frames-per-episode", "2",
            "--budgets", "1,4", "--agent", "uniform", "--agent", "oracle", "--seed", "4", "--no-progress"]
    assert main([*argv, "--out", str(tmp_path / "a")]) == 0
    with (tmp_path / "a" / "frames.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 2 * 2 * 2  # agents x budgets x frames
    assert all(int(r["n_hypotheses"]) == int(r["budget"]) for r in rows)
    summary = json.loads((tmp_path / "a" / "summary.json").read_text())
    assert summary["settings"]["env_id"] == "vo_gym/StereoVOImages-v0"
    cells = {(r["agent"], r["budget"]): r for r in summary["rows"]}
    oracle = cells[("oracle (upper bound)", 1)]
    assert oracle["success"] >= cells[("uniform", 1)]["success"] and oracle["ci_low"] <= oracle["success"] <= oracle["ci_high"]
    assert (tmp_path / "a" / "success_vs_budget.png").stat().st_size > 0
    assert "Wilson 95 %" in capsys.readouterr().out
    assert main([*argv, "--no-plots", "--out", str(tmp_path / "b")]) == 0  # same seed, same rows
    assert (tmp_path / "b" / "frames.csv").read_text() == (tmp_path / "a" / "frames.csv").read_text()


@pytest.mark.parametrize("source, needle", [("kitti:/data", "evaluate runs on rendered images"),
                                            ("bogus", "--source must be one of rendered")])
def test_evaluate_source_errors_are_one_line(tmp_path, capsys, source, needle):
    assert main(["evaluate", "--source", source, "--out", str(tmp_path / "e")]) == 2
    assert needle in _one_line(capsys, "evaluate")
    assert not (tmp_path / "e").exists()
