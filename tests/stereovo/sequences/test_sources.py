"""stereovo.sequences.sources: source strings, their errors, and image odometry over a source."""

from __future__ import annotations

import numpy as np
import pytest

from stereovo.geometry import relative_motion, rotation_error
from stereovo.sequences import open_source, run_image_odometry
from stereovo.sequences.sources import TrajectoryEstimate, parse_source
from tests.support.images import write_image_folder, write_kitti


pytest.importorskip("cv2", reason="the image front end needs OpenCV: pip install 'vo-gym[images]'")


def test_kitti_without_poses_still_runs_odometry(tmp_path, short):
    write_kitti(tmp_path, short, "00", with_poses=False)
    seq = open_source(f"kitti:{tmp_path}:00")
    assert seq.true_poses is None and seq.frame(1).truth is None
    result = run_image_odometry(seq)
    assert isinstance(result, TrajectoryEstimate) and result.poses.shape == (4, 4, 4) and result.ok.all()
    for k in range(3):  # every step, rotation and translation (each step turns by 0.8-1.3 deg)
        R, t = relative_motion(short.true_poses[k], short.true_poses[k + 1])
        est_R, est_t = relative_motion(result.poses[k], result.poses[k + 1])
        assert np.degrees(rotation_error(est_R, R)) < 0.1 and np.linalg.norm(est_t - t) < 0.05


@pytest.mark.parametrize("text, parsed", [
    ("rendered", ("rendered", {})),
    ("rendered:free", ("rendered", {"preset": "free"})),
    ("kitti:/data/kitti:05", ("kitti", {"root": "/data/kitti", "sequence": "05"})),
    ("kitti:/data/kitti/sequences/05", ("kitti", {"root": "/data/kitti/sequences/05", "sequence": None})),
])
def test_source_strings(text, parsed):
    assert parse_source(text) == parsed


@pytest.mark.parametrize("text", ["", "kitti", "kitti:", "euroc:/x", 3])
def test_bad_source_strings_are_named(text):
    with pytest.raises(ValueError, match="source must be one of rendered, rendered:PRESET, kitti:PATH"):
        parse_source(text)


def test_rendered_odometry_scores_a_short_run(short):
    result = run_image_odometry(short)
    assert result.n_frames == 3 and result.column("success").all()
    assert result.trajectory.ate_aligned_m < 0.05


def test_a_folder_whose_name_ends_in_colon_digits_is_that_folder(tmp_path):
    """kitti:/path/seq:2024 was read as sequence 2024 of /path/seq even where /path/seq:2024 is a folder."""
    folder = write_image_folder(tmp_path / "seq:2024")
    assert parse_source(f"kitti:{folder}") == ("kitti", {"root": str(folder), "sequence": None})
    assert len(open_source(f"kitti:{folder}")) == 2
    assert parse_source(f"kitti:{tmp_path / 'seq'}:7") == ("kitti", {"root": str(tmp_path / "seq"), "sequence": "7"})
