"""Shared fixtures: the default camera and reproducible noise-free / noisy frames."""

from __future__ import annotations

import os

import pytest
from hypothesis import settings

from stereovo.camera import StereoCamera

# CI machines have 2 shared cores: keep property-based tests bounded and deterministic.
settings.register_profile("ci", max_examples=60, deadline=None, derandomize=True)
settings.register_profile("dev", max_examples=60, deadline=None)
settings.load_profile("ci" if os.environ.get("CI") else "dev")


@pytest.fixture
def camera() -> StereoCamera:
    return StereoCamera()
