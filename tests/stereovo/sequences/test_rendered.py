"""stereovo.sequences.rendered: the rendered world's poses, depth, labels and errors."""

from __future__ import annotations

import numpy as np
import pytest

from stereovo.estimation import estimate_motion
from stereovo.geometry import relative_motion
from stereovo.metrics import frame_metrics
from stereovo.sequences import FrameSequence
from stereovo.simulation import OutlierKind, Sequence, SimulationConfig
from tests.support.images import rendered


pytest.importorskip("cv2", reason="the image front end needs OpenCV: pip install 'vo-gym[images]'")


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
    assert set(np.unique(ids)) == {0, 1, 2}  # the static world and both cars are in view
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
