"""``vo-gym vo`` (vo_gym_cli.commands.vo) end to end: its outputs (trajectories, frames, covariances,
plot), every method and learned sampler, image sources, and its argument errors."""

from __future__ import annotations

import argparse
import csv
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from stereovo.io import read_kitti, read_tum
from tests.support.cli import ROOT, one_line_error
from vo_gym_cli.commands.vo import parse_outliers
from vo_gym_cli.main import main


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


def _hypotheses(out: Path) -> list[int]:
    with (out / "frames.csv").open() as fh:
        return [int(float(r["n_hypotheses"])) for r in csv.DictReader(fh)]


SOURCE_OUTPUTS = ["trajectory_est.tum", "trajectory_true.tum", "trajectory_est.kitti.txt", "trajectory_true.kitti.txt",
           "frames.csv", "covariances.npy", "odometry.png", "summary.json"]


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


def test_config_error_is_reported_not_raised(tmp_path, capsys):
    # The AUC range is the simulator's rule: its ValueError becomes a message and exit code 2.
    code = main(["vo", "--auc", "0.3", "--frames", "2", "--out", str(tmp_path / "x"), "--no-progress"])
    assert code == 2
    err = capsys.readouterr().err
    assert "error: --auc must be a finite number in [0.5, 1), got 0.3" in err and "Traceback" not in err
    assert not (tmp_path / "x").exists()


def test_the_hostile_preset_reaches_the_simulated_sequence(tmp_path, capsys):
    from stereovo.simulation import OUTLIER_PRESETS
    from vo_gym_cli.commands.arguments import OUTLIER_PRESETS as named

    assert named == tuple(OUTLIER_PRESETS)
    argv = ["vo", "--frames", "3", "--n", "200", "--seed", "5", "--no-progress"]
    assert main([*argv, "--out", str(tmp_path / "default")]) == 0
    assert main([*argv, "--outlier-preset", "hostile", "--out", str(tmp_path / "hostile")]) == 0
    summary = json.loads((tmp_path / "hostile" / "summary.json").read_text())
    assert summary["settings"]["outlier_preset"] == "hostile"
    assert "outliers 0.5 (hostile)" in capsys.readouterr().out
    true_default, _ = read_tum(tmp_path / "default" / "trajectory_true.tum")
    true_hostile, _ = read_tum(tmp_path / "hostile" / "trajectory_true.tum")
    np.testing.assert_array_equal(true_default, true_hostile)  # the same motion, other match errors
    assert (tmp_path / "default" / "frames.csv").read_text() != (tmp_path / "hostile" / "frames.csv").read_text()
    with pytest.raises(SystemExit) as exc:
        main([*argv, "--outlier-preset", "sky", "--out", str(tmp_path / "x")])
    assert exc.value.code == 2
    assert "--outlier-preset" in capsys.readouterr().err and not (tmp_path / "x").exists()


def test_settings_the_simulator_cannot_draw_from_are_one_line_and_write_nothing(tmp_path, capsys):
    # --noise 200 passes its range, but no moving object can clear the outlier threshold of 1600 px
    code = main(["vo", "--noise", "200", "--frames", "2", "--n", "60", "--out", str(tmp_path / "x"), "--no-progress"])
    assert code == 2
    line = one_line_error(capsys, "vo")
    assert "noise_sigma=200.0 px" in line and "lower noise_sigma" in line
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
    assert "does not sample" in one_line_error(capsys, "vo")
    assert not (tmp_path / "v").exists()


def test_vo_on_a_rendered_source_writes_trajectory_drift_and_plot(tmp_path, capsys, short):
    from stereovo.io import read_tum

    out = tmp_path / "r"
    assert main(["vo", "--source", "rendered", "--resolution", "vga", "--frames", "3", "--seed", "4",
                 "--no-progress", "--out", str(out)]) == 0
    for name in SOURCE_OUTPUTS:
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


def test_the_detector_reaches_the_front_end_and_is_refused_without_images(tmp_path, capsys):
    from stereovo.frontend.options import DETECTORS
    from vo_gym_cli.commands.arguments import DETECTORS as named

    assert named == DETECTORS
    assert main(["vo", "--detector", "sift", "--frames", "2", "--out", str(tmp_path / "s")]) == 2
    assert one_line_error(capsys, "vo").endswith("--detector sift applies to an image --source only, not to "
                                                 "simulated matches")
    assert not (tmp_path / "s").exists()
    out = tmp_path / "a"
    assert main(["vo", "--source", "rendered", "--resolution", "vga", "--frames", "2", "--seed", "4",
                 "--detector", "akaze", "--no-progress", "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["settings"]["detector"] == "akaze" and summary["metrics"]["success_rate"] == 1.0
    frames = (out / "frames.csv").read_text().splitlines()
    header = frames[0].split(",")
    inliers = [int(row.split(",")[header.index("n_inliers")]) for row in frames[1:]]
    capsys.readouterr()
    assert main(["vo", "--source", "rendered", "--resolution", "vga", "--frames", "2", "--seed", "4",
                 "--no-progress", "--out", str(tmp_path / "o")]) == 0
    assert json.loads((tmp_path / "o" / "summary.json").read_text())["settings"]["detector"] == "orb"
    orb = (tmp_path / "o" / "frames.csv").read_text().splitlines()
    assert inliers != [int(row.split(",")[header.index("n_inliers")]) for row in orb[1:]]  # another front end


def test_vo_on_a_kitti_folder_with_and_without_poses(tmp_path, capsys, short):
    from tests.support.images import write_kitti

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


def test_vo_on_a_kitti_folder_of_jpegs_with_data_after_their_end(tmp_path, capsys, short):
    """Cameras and tools append data after a JPEG's end-of-image marker: such images, baseline and
    progressive, were refused as truncated; they are read, and the run goes as on the PNGs."""
    import cv2
    from PIL import Image

    from tests.support.images import write_kitti

    folder = write_kitti(tmp_path / "data", short, "05")
    tail = np.random.default_rng(4).integers(0, 256, 1024, np.uint8).tobytes()
    for k, png in enumerate(sorted(folder.glob("image_*/*.png"))):
        with Image.open(png) as image:
            image.save(png.with_suffix(".jpg"), quality=95, progressive=k % 2 == 1)
        png.unlink()
        png.with_suffix(".jpg").write_bytes(png.with_suffix(".jpg").read_bytes() + tail)
        assert cv2.imread(str(png.with_suffix(".jpg")), cv2.IMREAD_UNCHANGED) is not None
    out = tmp_path / "k"
    assert main(["vo", "--source", f"kitti:{tmp_path / 'data'}:05", "--no-progress", "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["metrics"]["frames"] == 3 and summary["metrics"]["success_rate"] == 1.0


@pytest.mark.parametrize("damage, needle", [
    ("truncated", "000001.png: not a readable image"),
    ("truncated jpeg", "000001.jpg: a truncated JPEG (its "),
    ("right smaller", "image pair 1"),
])
def test_a_bad_image_later_in_a_kitti_sequence_is_one_line_and_leaves_out_as_it_was(tmp_path, capsys, short,
                                                                                      damage, needle):
    # only the first pair is read when the sequence opens: a later one failed with a traceback
    import cv2

    from tests.support.images import write_kitti

    folder = write_kitti(tmp_path / "data", short, "05")
    if damage == "truncated":
        image = folder / "image_0" / "000001.png"
        image.write_bytes(image.read_bytes()[: image.stat().st_size // 2])
    elif damage == "truncated jpeg":  # (OpenCV decodes it, its missing part grey)
        image = folder / "image_0" / "000001.png"
        ok, data = cv2.imencode(".jpg", cv2.imread(str(image), cv2.IMREAD_UNCHANGED))
        image.unlink()
        image.with_suffix(".jpg").write_bytes(data.tobytes()[: data.size // 2])
    else:
        image = folder / "image_1" / "000001.png"
        cv2.imwrite(str(image), cv2.imread(str(image), cv2.IMREAD_GRAYSCALE)[:-8, :-8])
    out = tmp_path / "k"
    assert main(["vo", "--source", f"kitti:{tmp_path / 'data'}:05", "--no-progress", "--out", str(out)]) == 2
    line = one_line_error(capsys, "vo")
    assert line.startswith("vo-gym vo: error: --source kitti:") and needle in line, line
    assert not out.exists()


def _header_only_png(width: int, height: int) -> bytes:
    """A PNG that declares ``width`` x ``height`` grey pixels and holds 64 zero bytes of data."""
    import struct
    import zlib

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(b"\0" * 64)) + chunk(b"IEND", b""))


@pytest.mark.parametrize("image", ["image_0/000000.png", "image_1/000002.png"])
def test_an_image_declaring_too_many_pixels_is_one_line_and_leaves_out_as_it_was(tmp_path, capsys, image):
    """A header claiming 100000x100000 px made OpenCV raise cv2.error: a traceback (and, for a later image,
    an empty --out left behind). It is one line naming the file, from its header, before decoding."""
    pytest.importorskip("cv2")
    from PIL import Image

    from tests.support.images import write_image_folder

    folder = write_image_folder(tmp_path / "seq")
    (folder / image).write_bytes(_header_only_png(100000, 100000))
    out = tmp_path / "k"
    assert main(["vo", "--source", f"kitti:{folder}", "--no-progress", "--out", str(out)]) == 2
    line = one_line_error(capsys, "vo")
    assert line.startswith(f"vo-gym vo: error: --source kitti:{folder}") and line.endswith(
        # (Pillow refuses, without the size, over twice its own limit)
        f"{image}: declares an image of more than {2 * Image.MAX_IMAGE_PIXELS:,} pixels; images of at most 50,000,000 "
        "pixels are read (MAX_IMAGE_PIXELS)"), line
    assert not out.exists()


def test_an_opencv_error_or_a_crash_during_the_run_leaves_out_as_it_was(tmp_path, capsys, monkeypatch):
    """Should OpenCV's own error reach the command while the sequence is read, it is one line (exit 2),
    not a traceback; any other error still propagates, but without the --out folder it created."""
    cv2 = pytest.importorskip("cv2")
    from stereovo.sequences.kitti import KittiOdometry
    from tests.support.images import write_image_folder

    folder = write_image_folder(tmp_path / "seq")
    real = KittiOdometry.load_images
    for error, expected in ((cv2.error("Failed to allocate 8589934592 bytes"), 2), (RuntimeError("a bug"), None)):
        def load_images(self, k, error=error):
            if k == 2:
                raise error
            return real(self, k)

        monkeypatch.setattr(KittiOdometry, "load_images", load_images)
        out = tmp_path / "k"
        argv = ["vo", "--source", f"kitti:{folder}", "--no-progress", "--out", str(out)]
        if expected is None:
            with pytest.raises(RuntimeError, match="a bug"):
                main(argv)
        else:
            assert main(argv) == expected
            assert one_line_error(capsys, "vo").endswith(f"--source kitti:{folder}: Failed to allocate 8589934592 "
                                                         "bytes")
        assert not out.exists()


def test_a_learned_sampler_on_frames_without_matches_fails_the_frames_and_goes_on(tmp_path, capsys):
    """Blank images give frames of no matches: a one-shot sampler's guided weights took the maximum of
    no logits and aborted the run (exit 2, numpy's message); the frames now fail, as without --agent."""
    pytest.importorskip("cv2")
    pytest.importorskip("torch")
    from tests.support.images import write_image_folder

    folder = write_image_folder(tmp_path / "blank", blank=True)
    for agent in ([], ["--agent", "ngransac-supervised"]):
        out = tmp_path / f"run{len(agent)}"
        assert main(["vo", "--source", f"kitti:{folder}", "--frames", "2", "--method", "msac", *agent,
                     "--no-progress", "--out", str(out)]) == 0
        metrics = json.loads((out / "summary.json").read_text())["metrics"]
        assert metrics["frames"] == 2 and metrics["failed_frames"] == 2, metrics
    assert "2 failed" in capsys.readouterr().out


@pytest.mark.parametrize("source, needle", [
    ("bogus", "--source must be one of rendered, rendered:PRESET, kitti:PATH, kitti:PATH:SEQ, got 'bogus'"),
    ("rendered:plane", "--source 'rendered:plane': the rendered preset must be one of car, free, got 'plane'"),
])
def test_bad_source_strings_are_one_line_and_write_nothing(tmp_path, capsys, source, needle):
    with pytest.raises(SystemExit) as exc:
        main(["vo", "--source", source, "--out", str(tmp_path / "v")])
    assert exc.value.code == 2
    assert needle in one_line_error(capsys, "vo")
    assert not (tmp_path / "v").exists()


def test_a_missing_kitti_folder_is_one_line_naming_source(tmp_path, capsys):
    pytest.importorskip("cv2")
    assert main(["vo", "--source", f"kitti:{tmp_path / 'none'}", "--out", str(tmp_path / "v")]) == 2
    line = one_line_error(capsys, "vo")
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
    line = one_line_error(capsys, "vo")
    assert f"'{extra}' extra ({missing} is not installed): pip install 'vo-gym[{extra}]'" in line
    assert not (tmp_path / "v").exists()


def test_vo_command_writes_one_covariance_per_frame(tmp_path):
    from vo_gym_cli.main import main

    out = tmp_path / "run"
    assert main(["vo", "--frames", "6", "--n", "200", "--outliers", "0.4", "--seed", "2", "--out", str(out),
                 "--no-progress"]) == 0
    cov = np.load(out / "covariances.npy")
    assert cov.shape == (6, 6, 6)
    ok = np.all(np.isfinite(cov), axis=(1, 2))
    assert ok.all()  # an easy sequence: every frame estimated
    assert np.all(np.linalg.eigvalsh(cov) > 0)


@pytest.mark.parametrize("argv", [["--method", "prosac"], ["--method", "guided-mlesac"],
                                  ["--method", "msac", "--agent", "ngransac-supervised"]])
def test_vo_runs_score_methods_and_learned_samplers(tmp_path, capsys, argv):
    out = tmp_path / "vo"
    assert main(["vo", *argv, "--frames", "4", "--n", "150", "--no-progress", "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["metrics"]["frames"] == 4 and summary["metrics"]["success_rate"] > 0
    assert (out / "trajectory_est.tum").read_text().count("\n") == 5


def test_vo_agent_errors_are_one_line(tmp_path, capsys):
    assert main(["vo", "--agent", "nope", "--frames", "2", "--out", str(tmp_path / "v")]) == 2
    assert "--agent" in one_line_error(capsys, "vo")
    assert main(["vo", "--agent", "ppo", "--method", "inlier-detection", "--frames", "2",
                 "--out", str(tmp_path / "v")]) == 2
    assert "does not sample" in one_line_error(capsys, "vo")


@pytest.mark.parametrize("args, needle", [
    (["--source", "rendered", "--outlier-preset", "hostile"],
     "--outlier-preset hostile applies to simulated matches only, not to --source rendered"),
    (["--source", "rendered", "--outliers", "0.3"], "--outliers 0.3 applies to simulated matches only"),
    (["--source", "rendered", "--outliers", "0.3:0.9"], "--outliers 0.3:0.9 applies to simulated matches only"),
    (["--source", "kitti:/data", "--n", "200"], "--n 200 applies to simulated matches only, not to --source kitti:/data"),
    (["--source", "rendered:free", "--auc", "0.9"], "--auc 0.9 applies to simulated matches only"),
    (["--resolution", "vga"], "--resolution vga applies to a rendered --source only, not to simulated matches"),
    (["--source", "kitti:/data", "--resolution", "vga"],
     "--resolution vga applies to a rendered --source, not to --source kitti:/data"),
    (["--source", "kitti:/data", "--preset", "free"], "--preset free applies to a rendered --source or simulated matches, not to"),
    (["--source", "rendered:free", "--preset", "car"], "--preset car contradicts --source rendered:free"),
])
def test_an_option_the_input_would_ignore_is_refused_naming_it(tmp_path, capsys, args, needle):
    assert main(["vo", *args, "--out", str(tmp_path / "v")]) == 2
    assert needle in one_line_error(capsys, "vo")
    assert not (tmp_path / "v").exists()


@pytest.mark.parametrize("method", ["prosac", "guided-mlesac"])
def test_an_in_frame_agent_with_a_method_it_cannot_drive_is_one_line(tmp_path, capsys, method):
    # was a traceback from the first estimate: these methods need priors= or order= from the caller
    assert main(["vo", "--agent", "adaptive-pg-prior", "--method", method, "--frames", "2",
                 "--out", str(tmp_path / "v")]) == 2
    line = one_line_error(capsys, "vo")
    assert f"method {method!r} needs" in line and "in-frame sampler 'adaptive-pg-prior'" in line
    assert not (tmp_path / "v").exists()


@pytest.mark.parametrize("argv,message", [
    (["--noise", "1000"], "error: --noise must be small enough that the outlier threshold max(4, 8*noise_sigma) = "
                          "8000 px fits in the 1241x376 px image"),
    (["--auc", "0.3"], "error: --auc must be a finite number in [0.5, 1), got 0.3"),
])
def test_a_simulator_setting_is_named_by_its_flag_from_the_fields_error(tmp_path, capsys, argv, message):
    """The config's errors carry their field (OptionError.name): the flag is found by it, not by the
    message's words, for the composite fields' checks (outlier_ratio) as for the scalar ones."""
    code = main(["vo", *argv, "--n", "60", "--out", str(tmp_path / "x"), "--no-progress"])
    assert code == 2
    assert message in one_line_error(capsys, "vo")
    assert not (tmp_path / "x").exists()


def test_the_simulator_config_names_the_field_of_a_composite_check():
    from stereovo.options import OptionError
    from stereovo.simulation import SimulationConfig

    with pytest.raises(OptionError) as err:
        SimulationConfig(outlier_mix={"sky": 1.0})
    assert err.value.name == "outlier_mix" and err.value.rule.startswith(" must be a mapping from outlier kinds")
    assert str(err.value) == f"SimulationConfig.outlier_mix{err.value.rule}"
