"""SimulationConfig: validation naming the field, frozen variants, presets, and the options contract."""

from __future__ import annotations

import dataclasses
import math

import pytest

from stereovo.camera import StereoCamera
from stereovo.simulation import SimulationConfig, PRESETS


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
