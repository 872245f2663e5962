"""Frame sequences: the rendered world (poses, depth, labels, determinism), the KITTI loader on a
folder written in KITTI's layout, the simulator's adapter, source strings, and their errors."""

from __future__ import annotations

import numpy as np
import pytest

from images_support import rendered, write_kitti

pytest.importorskip("cv2", reason="the image front end needs OpenCV: pip install 'vo-gym[images]'")

from stereovo.estimation import estimate_motion  # noqa: E402
from stereovo.geometry import relative_motion  # noqa: E402
from stereovo.metrics import frame_metrics  # noqa: E402
from stereovo.sequences import (  # noqa: E402
    FrameSequence, KittiOdometry, SimulatedSequence, as_frame_sequence, open_source, run_image_odometry,
)
from stereovo.sequences.sources import TrajectoryEstimate, parse_source  # noqa: E402
from stereovo.simulation import OutlierKind, Sequence, SimulationConfig  # noqa: E402


@pytest.fixture(scope="module")
def short():
    sequence = rendered(preset="car", n_frames=3, resolution="vga", seed=21)
    yield sequence
    sequence.close()


def test_rendered_poses_are_the_simulators_trajectory(short):
    config = SimulationConfig(preset="car", n_frames=3, camera=short.camera)
    assert np.array_equal(short.true_poses, Sequence(config, 21).true_poses)
    assert isinstance(short, FrameSequence) and len(short) == 3 and short.n_images() == 4


def test_rendered_depth_agrees_with_the_projection_of_a_rendered_point(short):
    depth, ids = short.depth(0)
    cam = short.camera
    assert depth.shape == (cam.height, cam.width) and ids.shape == depth.shape
    assert (depth > 0).mean() > 0.5 and np.all(ids == 0)  # no moving objects asked for
    # a road pixel: the road lies CAMERA_HEIGHT below the first camera, so its depth follows from its row
    from stereovo.sequences.world import CAMERA_HEIGHT

    v = cam.height - 5
    u = int(cam.cx)
    z = CAMERA_HEIGHT * cam.fy / (v - cam.cy)
    assert depth[v, u] == pytest.approx(z, rel=0.02)


def test_moving_objects_are_labelled_as_moving():
    sequence = rendered(preset="car", n_frames=2, resolution="vga", seed=3, moving_objects=2)
    depth, ids = sequence.depth(1)
    assert set(np.unique(ids)) >= {0}
    frame = sequence.frame(2)
    kinds = np.bincount(frame.truth.outlier_kind, minlength=4)
    on_objects = ids[np.rint(frame.prev[:, 1]).astype(int), np.rint(frame.prev[:, 0]).astype(int)] > 0
    if on_objects.sum() >= 5:  # the cars ahead are seen: their matches are moving-object outliers
        assert kinds[int(OutlierKind.MOVING_OBJECT)] >= 0.8 * on_objects.sum()
    motions = sequence.motions(2)
    assert set(motions) == {0, 1, 2}
    R, t = relative_motion(sequence.true_poses[1], sequence.true_poses[2])
    assert np.allclose(motions[0][0], R) and np.allclose(motions[0][1], t)
    sequence.close()


def test_free_preset_renders_an_open_world_and_estimates_motion():
    sequence = rendered(preset="free", n_frames=2, resolution="vga", seed=4)
    assert sequence.world == "open"
    frame = sequence.frame(1)
    assert frame.n > 50 and frame.truth.inlier.mean() > 0.5
    est = estimate_motion(frame.prev, frame.curr, frame.camera, noise_sigma=0.5, rng=np.random.default_rng(0))
    assert frame_metrics(est, frame.truth).success
    sequence.close()


@pytest.mark.parametrize("kwargs, message", [
    ({"preset": "boat"}, "RenderedSequence: preset must be one of 'car', 'free', got 'boat'"),
    ({"resolution": "4k"}, "RenderedSequence: resolution must be one of 'kitti', 'vga', got '4k'"),
    ({"n_frames": 0}, "RenderedSequence: n_frames must be an integer >= 1"),
    ({"moving_objects": -1}, "RenderedSequence: moving_objects must be an integer >= 0"),
    ({"noise_sigma": 0.0}, "RenderedSequence: noise_sigma must be a finite number in (0, 100] (px), got 0.0"),
])
def test_rendered_sequence_errors_name_the_argument(kwargs, message):
    with pytest.raises(ValueError) as err:
        rendered(**kwargs)
    assert message in str(err.value)


def test_index_errors(short):
    with pytest.raises(IndexError, match=r"frame index must be an integer in \[1, 3\], got 0"):
        short.frame(0)
    with pytest.raises(IndexError, match=r"image index must be an integer in \[0, 3\], got 4"):
        short.images(4)


# ------------------------------------------------------------------ KITTI


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


def test_kitti_without_poses_still_runs_odometry(tmp_path, short):
    write_kitti(tmp_path, short, "00", with_poses=False)
    seq = open_source(f"kitti:{tmp_path}:00")
    assert seq.true_poses is None and seq.frame(1).truth is None
    result = run_image_odometry(seq)
    assert isinstance(result, TrajectoryEstimate) and result.poses.shape == (4, 4, 4) and result.ok.all()
    R, t = relative_motion(short.true_poses[0], short.true_poses[1])
    est_R, est_t = relative_motion(result.poses[0], result.poses[1])
    assert np.linalg.norm(est_t - t) < 0.05


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


# ------------------------------------------------------------------ one interface


def test_the_simulators_adapter_gives_the_same_frames():
    config = SimulationConfig(n_frames=2, n_correspondences=20)
    seq = Sequence(config, 9)
    adapted = as_frame_sequence(seq)
    assert isinstance(adapted, SimulatedSequence) and isinstance(adapted, FrameSequence)
    assert adapted.camera == config.camera and len(adapted) == 2
    for a, b in zip(adapted, Sequence(config, 9)):
        assert np.array_equal(a.prev, b.prev) and np.array_equal(a.scores, b.scores)
    with pytest.raises(TypeError, match="not a frame sequence"):
        as_frame_sequence([1, 2])


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
