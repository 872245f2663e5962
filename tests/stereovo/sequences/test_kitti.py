"""stereovo.sequences.kitti: the KITTI loader on a folder written in KITTI's layout, and its errors."""

from __future__ import annotations

import numpy as np
import pytest

from stereovo.estimation import estimate_motion
from stereovo.metrics import frame_metrics
from stereovo.sequences import KittiOdometry
from tests.support.images import write_kitti


pytest.importorskip("cv2", reason="the image front end needs OpenCV: pip install 'vo-gym[images]'")


@pytest.fixture(scope="module")
def kitti_root(tmp_path_factory, short):
    root = tmp_path_factory.mktemp("kitti")
    write_kitti(root, short, "07")
    return root


def test_kitti_loader_reads_the_rig_the_images_and_the_poses(kitti_root, short):
    seq = KittiOdometry(kitti_root, 7)
    cam, ref = seq.camera, short.camera
    assert (cam.width, cam.height) == (ref.width, ref.height)
    assert cam.fx == pytest.approx(ref.fx) and cam.cx == pytest.approx(ref.cx) and cam.cy == pytest.approx(ref.cy)
    assert cam.baseline == pytest.approx(ref.baseline)
    assert len(seq) == 3 and np.allclose(seq.true_poses, short.true_poses, atol=1e-9)
    for k in range(4):
        assert np.array_equal(seq.images(k)[0], short.images(k)[0])
    frame = seq.frame(2)
    assert np.array_equal(frame.prev, short.frame(2).prev)
    est = estimate_motion(frame.prev, frame.curr, frame.camera, noise_sigma=0.5, rng=np.random.default_rng(0))
    metrics = frame_metrics(est, frame.truth)
    assert metrics.success and frame.truth.inlier.mean() > 0.6


def test_kitti_loader_takes_a_sequence_folder_and_a_range(kitti_root):
    seq = KittiOdometry(kitti_root / "sequences" / "07", None, start=1)
    assert len(seq) == 2 and seq.poses_file is not None  # ../../poses/07.txt
    assert np.allclose(seq.true_poses[0], np.eye(4))


def test_kitti_errors_name_the_file(tmp_path, short):
    with pytest.raises(FileNotFoundError, match="no folder"):
        KittiOdometry(tmp_path / "missing")
    folder = write_kitti(tmp_path, short, "01")
    with pytest.raises(FileNotFoundError, match="no sequence folder"):
        KittiOdometry(tmp_path, "02")
    calib = folder / "calib.txt"
    text = calib.read_text()
    calib.write_text(text.replace("P1:", "P9:"))
    with pytest.raises(ValueError, match=r"calib.txt: no P1 line"):
        KittiOdometry(tmp_path, "01")
    calib.write_text(text.replace("P1:", "P1: oops"))
    with pytest.raises(ValueError, match=r"calib.txt, line 2: P1 must be 12 numbers"):
        KittiOdometry(tmp_path, "01")
    calib.write_text(text)
    (folder / "image_1" / "000003.png").unlink()
    with pytest.raises(ValueError, match="4 left images but 3 right images"):
        KittiOdometry(tmp_path, "01")


def test_kitti_pose_and_calibration_lines_need_twelve_finite_numbers(tmp_path):
    from stereovo.sequences.kitti import read_calibration, read_poses

    poses = tmp_path / "00.txt"
    poses.write_text("1 0 0 0 0 1 0 0 0 0 1 0\n\n1 0 0 0 0 1 0 0 0 0 1 2.5\n")
    assert read_poses(poses).shape == (2, 4, 4) and read_poses(poses)[1, 2, 3] == 2.5
    for line, message in (("1 0 0 0 0 1 0 0 0 0 1 x", r"line 1: a pose must be 12 numbers, got '1 0 0 0 0 1 0 0 0 0 1 x'$"),
                          ("1 0 0 0 0 1 0 0 0 0 1", r"line 1: a pose must be 12 finite numbers, got 11$"),
                          ("1 0 0 0 0 1 0 0 0 0 1 nan", r"line 1: a pose must be 12 finite numbers, got 12$"),
                          # finite, but no camera pose: the drift's SVD failed far from the file
                          ("1e308 0 0 1e308 0 1e308 0 0 0 0 1e308 0", r"line 1: a pose must be a rotation and a position"),
                          ("0 0 0 0 0 0 0 0 0 0 0 0", r"line 1: a pose must be a rotation"),
                          ("-1 0 0 0 0 1 0 0 0 0 1 0", r"line 1: a pose must be a rotation"),
                          ("1 0 0 1e300 0 1 0 0 0 0 1 0", r"within 1e\+07 m, got '1 0 0 1e300")):
        poses.write_text(line + "\n")
        with pytest.raises(ValueError, match=message):
            read_poses(poses)
    calib = tmp_path / "calib.txt"
    calib.write_text("P0: 700 0 600 0 0 700 180 0 0 0 1 0\nP1: 700 0 600 -378 0 700 180 0 0 0 1 inf\n")
    with pytest.raises(ValueError, match=r"calib.txt, line 2: P1 must be 12 finite numbers, got 12$"):
        read_calibration(calib)
    calib.write_text("P0: 700 0 600 0 0 700 180 0 0 0 1 0\nP1: 700 0 600 -378 0 700 180 0 0 0 1 0\n"
                     "P1: 700 0 600 -700 0 700 180 0 0 0 1 0\n")
    with pytest.raises(ValueError, match=r"calib.txt, line 3: a second P1 line$"):
        read_calibration(calib)


@pytest.mark.parametrize("p0, message", [
    ("700 0.5 600 0 0 700 180 0 0 0 1 0", r"P0\[0, 1\] is 0.5; a rectified pair's projection has 0 there"),
    ("700 0 600 0 0 700 180 0 0 0 2 0", r"P0\[2, 2\] is 2; a rectified pair's projection has 1 there"),
    ("700 0 600 0 0 700 180 3 0 0 1 0", r"P0\[1, 3\] is 3;"),
    ("700 0 600 0 0 700 180 0 0 0 1 0.1", r"P0\[2, 3\] is 0.1;"),
    ("-700 0 600 0 0 700 180 0 0 0 1 0", r"P0 has focal lengths fx=-700, fy=700 px; both must be at least 1 px"),
])
def test_kitti_calibration_must_be_a_rectified_pair(tmp_path, p0, message):
    """A projection of another form would be read as some other camera: skew, a scaled third row, a
    vertical or depth offset and a negative focal length are refused, naming the file and the entry."""
    from stereovo.sequences.kitti import read_calibration

    calib = tmp_path / "calib.txt"
    calib.write_text(f"P0: {p0}\nP1: 700 0 600 -378 0 700 180 0 0 0 1 0\n")
    with pytest.raises(ValueError, match=r"calib.txt: " + message):
        read_calibration(calib)
    calib.write_text(f"P0: 700 0 600 0 0 700 180 0 0 0 1 0\nP1: {p0.replace(' 600 0 ', ' 600 -378 ', 1)}\n")
    with pytest.raises(ValueError, match=r"calib.txt: " + message.replace("P0", "P1")):
        read_calibration(calib)


def test_kitti_calibration_absurd_numbers_are_refused_naming_the_file(tmp_path):
    from stereovo.sequences.kitti import read_calibration

    calib = tmp_path / "calib.txt"
    calib.write_text("P0: 700 0 nan 0 0 700 180 0 0 0 1 0\n")
    with pytest.raises(ValueError, match="12 finite numbers"):
        read_calibration(calib)
    calib.write_text("P0: 1e-30 0 600 0 0 1e-30 180 0 0 0 1 0\nP1: 1e-30 0 600 -1e-30 0 1e-30 180 0 0 0 1 0\n")
    with pytest.raises(ValueError, match=r"calib.txt: P0 has focal lengths fx=1e-30, fy=1e-30 px; both must be at least 1 px"):
        read_calibration(calib)
    calib.write_text("P0: 700 0 600 0 0 700 180 0 0 0 1 0\nP1: 700 0 600 -2.1e300 0 700 180 0 0 0 1 0\n")
    with pytest.raises(ValueError, match=r"calib.txt: P1 puts the right camera at baseline 3e\+297 m; expected in \(0, 1e\+07\]"):
        read_calibration(calib)


def test_kitti_principal_point_outside_the_images_is_refused(tmp_path, short):
    """A calibration written for another image size (the principal point off the images) is refused
    by the loader, which knows the images' size; the file is named with the point and the size."""
    folder = write_kitti(tmp_path, short, "03")
    calib = folder / "calib.txt"
    lines = calib.read_text().splitlines()
    numbers = lines[0].split()[1:]
    cx = float(numbers[2])
    calib.write_text("\n".join(line.replace(f" {numbers[2]} ", f" {cx + 5000:g} ", 1) for line in lines) + "\n")
    with pytest.raises(ValueError, match=r"calib.txt puts the principal point at \(\d+(\.\d+)?, [\d.]+\) px, "
                                         r"outside the \d+x\d+ images of .*image_0"):
        KittiOdometry(tmp_path, "03")
