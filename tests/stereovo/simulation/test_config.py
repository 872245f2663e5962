"""SimulationConfig: validation naming the field, frozen variants, presets, and the options contract."""

from __future__ import annotations

import dataclasses
import math
import re

import numpy as np
import pytest

from stereovo.camera import StereoCamera
from stereovo.simulation import PRESETS, SimulationConfig
from stereovo.simulation.config import MAX_FRAMES


@pytest.mark.parametrize("name,value", [("n_frames", 2.0), ("n_correspondences", True), ("noise_sigma", 1e300),
                                        ("noise_sigma", "0.5"), ("score_auc", math.nan), ("preset", 3),
                                        ("z_min", math.inf), ("speed", complex(1, 1))])
def test_simulator_fields_follow_the_contract(name, value):
    with pytest.raises(ValueError, match=rf"^SimulationConfig\.{name} must be"):
        SimulationConfig(**{name: value})


def test_invalid_noise_message_names_field_and_value() -> None:
    with pytest.raises(ValueError, match=r"^SimulationConfig\.noise_sigma must be a finite number in \[0, 1000\] \(px\), got -1$"):
        SimulationConfig(noise_sigma=-1)


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"noise_sigma": float("nan")}, "noise_sigma"),
        ({"outlier_ratio": 1.0}, "outlier_ratio"),
        ({"outlier_ratio": -0.1}, "outlier_ratio"),
        ({"outlier_ratio": (0.6, 0.2)}, "outlier_ratio"),
        ({"outlier_ratio": (0.2, 1.0)}, "outlier_ratio"),
        ({"preset": "boat"}, "preset"),
        ({"world": "moon"}, "world"),
        ({"n_correspondences": 2}, "n_correspondences"),
        ({"n_correspondences": 10.5}, "n_correspondences"),
        ({"n_frames": 0}, "n_frames"),
        ({"outlier_mix": (0.0, 0.0, 0.0)}, "outlier_mix"),
        ({"outlier_mix": (1.0, -1.0, 1.0)}, "outlier_mix"),
        ({"outlier_mix": (1.0, 1.0)}, "outlier_mix"),
        ({"score_auc": 1.0}, "score_auc"),
        ({"score_auc": 0.4}, "score_auc"),
        ({"z_min": 0.0}, "z_min"),
        ({"z_min": 10.0, "z_max": 5.0}, "z_max"),
        ({"speed": -1.0}, "speed"),
        ({"camera": "kitti"}, "camera"),
    ],
)
def test_invalid_config_raises_naming_the_field(kwargs: dict, field: str) -> None:
    with pytest.raises(ValueError, match=rf"SimulationConfig\.{field} must"):
        SimulationConfig(**kwargs)


def test_camera_with_empty_image_is_rejected() -> None:
    with pytest.raises(ValueError, match="width"):
        SimulationConfig(camera=StereoCamera(width=0))


def test_config_is_frozen_and_variants_use_replace() -> None:
    config = SimulationConfig()
    with pytest.raises(dataclasses.FrozenInstanceError):
        config.noise_sigma = 1.0  # type: ignore[misc]
    variant = dataclasses.replace(config, preset="free", outlier_ratio=(0.1, 0.4))
    assert variant.resolved_world == "open" and config.resolved_world == "street"
    assert variant.epsilon_range == (0.1, 0.4) and config.epsilon_range == (0.5, 0.5)
    assert hash(config) == hash(SimulationConfig())
    with pytest.raises(ValueError, match="outlier_ratio"):
        dataclasses.replace(config, outlier_ratio=1.0)


def test_presets_describe_car_and_free_motion() -> None:
    car, free = PRESETS["car"], PRESETS["free"]
    assert car.speed == pytest.approx(1.0) and free.speed < car.speed
    pitch, yaw, roll = car.angular_std
    assert yaw > 5 * max(pitch, roll)  # camera y points down: yaw is about y
    assert min(free.angular_std) > 0.2 * max(free.angular_std)
    assert SimulationConfig(speed=2.0).motion.speed == 2.0


@pytest.mark.parametrize("kwargs,field,text", [
    ({"outlier_ratio": 10**400}, "outlier_ratio", "~1e+400 (an integer of 401 digits)"),
    ({"outlier_ratio": (0, 10**400)}, "outlier_ratio", "(0, ~1e+400 (an integer of 401 digits))"),
    ({"outlier_mix": {"random": 10**400}}, "outlier_mix", "{'random': ~1e+400 (an integer of 401 digits)}"),
    ({"outlier_mix": (1, 10**400, 0)}, "outlier_mix", "(1, ~1e+400 (an integer of 401 digits), 0)"),
    ({"noise_sigma": 10**400}, "noise_sigma", "~1e+400 (an integer of 401 digits)"),
    ({"z_max": 10**400}, "z_max", "~1e+400 (an integer of 401 digits)"),
    ({"outlier_mix": np.array(2)}, "outlier_mix", "array(2)"),
    ({"outlier_mix": np.ones((3, 2))}, "outlier_mix", None),
    ({"outlier_mix": {1: 0.5, "random": 1.0}}, "outlier_mix", None),
    ({"n_frames": 10**9}, "n_frames", "1000000000"),
])
def test_bad_values_are_a_value_error_naming_field_and_value(kwargs, field, text):
    """Never an OverflowError (float(10**400)) or numpy's 'len() of unsized object'."""
    tail = re.escape(text) if text is not None else ".*"
    with pytest.raises(ValueError, match=rf"(?s)^SimulationConfig\.{field} must be .*, got {tail}$"):
        SimulationConfig(**kwargs)


def test_outlier_mix_of_a_numpy_vector_and_the_frame_cap_stay_valid():
    assert SimulationConfig(outlier_mix=np.array([1, 1, 0])).outlier_mix == (1.0, 1.0, 0.0)
    assert SimulationConfig(n_frames=MAX_FRAMES).n_frames == 10**6
    with pytest.raises(ValueError, match=r"^SimulationConfig\.n_frames must be an integer >= 1 and <= 1000000, got 1000001$"):
        SimulationConfig(n_frames=MAX_FRAMES + 1)


def test_noise_whose_outlier_threshold_exceeds_the_image_is_refused_only_with_outliers():
    """8 sigma must fit within sqrt(2 * 1240^2 + 375^2) = 1793.27 px (the default image) when frames have outliers."""
    with pytest.raises(ValueError, match=r"^SimulationConfig\.noise_sigma must be small enough that the outlier "
                                         r"threshold max\(4, 8\*noise_sigma\) = 1800 px fits in the 1241x376 px image "
                                         r"\(at most 1793\.27 px .*\(outlier_ratio=0\.5\), got 225\.0$"):
        SimulationConfig(noise_sigma=225)
    with pytest.raises(ValueError, match=r"noise_sigma .*\(outlier_ratio=\(0\.0, 0\.2\)\), got 1000\.0$"):
        SimulationConfig(noise_sigma=1000, outlier_ratio=(0.0, 0.2), outliers="hostile")
    assert SimulationConfig(noise_sigma=224.0).noise_sigma == 224.0  # fits: valid (the draw decides)
    for no_outliers in ({"outlier_ratio": 0.0}, {"outlier_ratio": 0.004, "n_correspondences": 100}):  # round(0.4) = 0
        assert SimulationConfig(noise_sigma=1000, **no_outliers).noise_sigma == 1000.0


def test_cameras_that_see_no_depth_of_the_range_are_refused():
    tiny = StereoCamera(width=2, height=2)  # fx b / z <= 1 px needs z >= 386 m
    with pytest.raises(ValueError, match=r"^SimulationConfig\.z_max must be large enough that fx\*baseline/z_max fits in "
                                         r"the image \(at most width - 1 = 1 px; at z_max it is 6\.43616 px\), got 60\.0$"):
        SimulationConfig(camera=tiny)
    with pytest.raises(ValueError, match=r"^SimulationConfig\.camera must be an image that can hold an outlier"):
        SimulationConfig(camera=tiny, z_max=400.0)  # an outlier lies >= 4 px away: not in a 2x2 image
    assert SimulationConfig(camera=tiny, z_max=400.0, outlier_ratio=0.0).z_max == 400.0
    with pytest.raises(ValueError, match=r"^SimulationConfig\.camera must be a camera whose min_disparity \(9 px\) is "
                                         r"below width - 1 \(9 px\)"):
        SimulationConfig(camera=StereoCamera(width=10, min_disparity=9), z_min=0.1)


def test_outlier_weights_whose_split_overflows_are_refused():
    """pair._apportion splits the outliers by count * w / sum(w): (1e308,) * 3 sums to inf (a crash
    in the simulator); weights whose products stay finite keep working."""
    with pytest.raises(ValueError, match=r"^SimulationConfig\.outlier_mix must be weights whose sum, and whose products "
                                         r"with the outlier count \(250\), are finite floats .*got \(1e\+308, 1e\+308, 1e\+308\)$"):
        SimulationConfig(outlier_mix=(1e308, 1e308, 1e308))
    assert SimulationConfig(outlier_mix=(1e305, 1e305, 1e305)).outlier_mix == (1e305, 1e305, 1e305)
