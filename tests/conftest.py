"""Shared fixtures: the default camera and a simulated frame."""

from __future__ import annotations

import os

import pytest
from hypothesis import settings

from stereovo.camera import StereoCamera
from stereovo.simulation import SimulationConfig, simulate_frame

# CI machines have 2 shared cores: keep property-based tests bounded and deterministic.
settings.register_profile("ci", max_examples=60, deadline=None, derandomize=True)
settings.register_profile("dev", max_examples=60, deadline=None)
settings.load_profile("ci" if os.environ.get("CI") else "dev")


@pytest.fixture(autouse=True)
def quiet_compile_notice(monkeypatch):
    """No test hears the one-line compile notice (``stereovo.compilation``): numba compiles a kernel
    on its first call in a process without a cache, whichever test that is, and a test of one-line
    errors would then read two lines. The notice's own tests unset it."""
    from stereovo.compilation import QUIET_ENV

    monkeypatch.setenv(QUIET_ENV, "1")


@pytest.fixture
def camera() -> StereoCamera:
    return StereoCamera()


@pytest.fixture(scope="module")
def frame():
    """A frame of 300 correspondences at eps 0.3 (seed 11), made once per module."""
    return simulate_frame(SimulationConfig(n_correspondences=300, outlier_ratio=0.3), rng=11)
