"""Bad arguments of the simulator's entry points, and valid settings it cannot draw a frame for:
a clear error naming the argument or the settings, never numpy's message, an AttributeError or
a RuntimeError; the frames it draws today stay as they are (scripts/digests.py)."""

from __future__ import annotations

import re

import numpy as np
import pytest

from stereovo.camera import StereoCamera
from stereovo.simulation import Sequence, SimulationConfig, simulate_frame
from stereovo.simulation.config import InfeasibleSettingsError
from stereovo.simulation.frame import OutlierKind
from stereovo.simulation.pair import _add_noise, _valid

SMALL = SimulationConfig(n_correspondences=30, n_frames=2)


def test_simulate_frame_names_a_config_that_is_none():
    with pytest.raises(TypeError, match=r"^config must be a SimulationConfig, got NoneType$"):
        simulate_frame(None, 0)  # type: ignore[arg-type]


@pytest.mark.parametrize("rng,text", [(-1, "-1"), (True, "True"), (np.bool_(False), "np.False_"), (1.5, "1.5"),
                                      ("0", "'0'"), ([0], "[0]")])
def test_simulate_frame_names_a_bad_rng(rng, text):
    with pytest.raises(ValueError, match=rf"^rng must be a numpy\.random\.Generator, a SeedSequence, an integer seed "
                                         rf">= 0 or None, got {re.escape(text)}$"):
        simulate_frame(SMALL, rng)


@pytest.mark.parametrize("seed,text", [(-1, "-1"), (True, "True"), (1.5, "1.5"), ("3", "'3'"),
                                       (np.random.default_rng(0), "Generator(PCG64)")])
def test_sequence_names_a_bad_seed(seed, text):
    with pytest.raises(ValueError, match=rf"^seed must be an integer >= 0, a numpy\.random\.SeedSequence or None, "
                                         rf"got {re.escape(text)}"):
        Sequence(SMALL, seed)


def test_every_documented_seed_still_gives_the_same_frames():
    one = simulate_frame(SMALL, 3)
    for same in (np.int64(3), np.random.default_rng(3), np.random.SeedSequence(3)):
        np.testing.assert_array_equal(simulate_frame(SMALL, same).curr, one.curr)
    assert simulate_frame(SMALL, None).n == 30 and simulate_frame(SMALL, 0).n == 30
    base = Sequence(SMALL, 7).frame(2).curr
    for same in (np.uint8(7), np.random.SeedSequence(7)):
        np.testing.assert_array_equal(Sequence(SMALL, same).frame(2).curr, base)
    assert len(Sequence(SMALL)) == 2 and Sequence(SMALL, 10**30).frame(1).n == 30


@pytest.mark.parametrize("kwargs,text", [
    ({"z_min": 59.9999}, "z_min=59.9999 m, z_max=60.0 m"),
    ({"z_max": 3.0000001}, "z_min=3.0 m, z_max=3.0000001 m"),
    ({"speed": 1000}, "speed=1000.0 m/frame (preset 'car')"),
    ({"camera": StereoCamera(cx=-1e6)}, "cx=-1000000.0"),
])
def test_settings_that_keep_no_landmark_in_view_raise_a_value_error_naming_them(kwargs, text):
    config = SimulationConfig(n_correspondences=20, n_frames=1, **kwargs)  # valid: whether a frame exists is the draw's
    with pytest.raises(InfeasibleSettingsError, match=r"^z_min=.* m, z_max=.* m, speed=.* m/frame .*, camera 1241x376 "
                                                      r"px \(cx=.*: found only 0 of 20 landmarks visible in both frames"):
        simulate_frame(config, 0)
    with pytest.raises(ValueError, match=re.escape(text)):  # a ValueError, from a Sequence's frame too
        Sequence(config, 0).frame(1)


def test_a_moving_object_that_cannot_show_by_the_outlier_threshold_is_a_value_error_naming_noise_sigma():
    config = SimulationConfig(noise_sigma=200, n_correspondences=60)
    with pytest.raises(InfeasibleSettingsError, match=r"^noise_sigma=200\.0 px, z_min=3\.0 m, z_max=60\.0 m, camera "
                                                      r"1241x376 px: could not place a visibly moving object .* = 1600 px"):
        simulate_frame(config, 0)
    # without the moving kind the same noise draws frames (its outliers do not need to show a motion)
    frame = simulate_frame(SimulationConfig(noise_sigma=200, n_correspondences=60, outlier_mix=(1.0, 1.0, 0.0)), 0)
    assert frame.n == 60


@pytest.mark.parametrize("kwargs,seed", [({"noise_sigma": 50}, 0), ({"noise_sigma": 200, "outliers": "hostile"}, 5)])
def test_heavy_noise_draws_that_hit_the_stereo_mismatch_fallback_give_a_frame(kwargs, seed):
    """These draws raised 'simulator bug: a noise-free measurement left the image': a stereo mismatch
    whose disparity floor (min_disparity + 3 sigma) exceeds its uL had its right point left of the
    image, and no noise draw brought it back. Its right point now sits on the image's edge."""
    frame = simulate_frame(SimulationConfig(n_correspondences=60, **kwargs), seed)
    kept = frame.truth.outlier_kind <= OutlierKind.MOVING_OBJECT  # the rows that are redrawn to stay usable
    assert _valid(frame.prev[kept], frame.camera).all() and _valid(frame.curr[kept], frame.camera).all()


def test_a_lost_stereo_row_takes_the_image_edge_only_when_no_noise_draw_fits():
    # noise far beyond a 20x20 image: a redraw fits about once in 10**6
    config = SimulationConfig(noise_sigma=1000, outlier_ratio=0.0, camera=StereoCamera(width=20, height=20))
    meas = np.array([[5.0, 10.0, -3.0, 10.0]])  # a noise-free right point left of the image
    out = _add_noise(meas, np.full((1, 3), 50.0), config, np.random.default_rng(0))
    np.testing.assert_array_equal(out, [[5.0, 10.0, 0.0, 10.0]])
    # a draw that brings it into the image is kept, as it always was
    out = _add_noise(meas, np.array([[0.0, 0.0, 0.004]]), config, np.random.default_rng(0))
    np.testing.assert_allclose(out, [[5.0, 10.0, 1.0, 10.0]])


def test_any_other_row_the_image_cannot_hold_takes_the_widest_disparity():
    camera = StereoCamera(width=11, height=11, cx=5.0, cy=5.0, min_disparity=9.5)
    config = SimulationConfig(noise_sigma=1000, outlier_ratio=0.0, camera=camera)
    meas = np.array([[9.2, 5.0, 0.5, 5.0]])  # disparity 8.7 px <= min_disparity, both pixels inside
    out = _add_noise(meas, np.full((1, 3), 50.0), config, np.random.default_rng(0))
    np.testing.assert_array_equal(out, [[10.0, 5.0, 0.0, 5.0]])
