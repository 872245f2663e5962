"""Helpers for the front-end tests: the small camera, a texture and the rendered frames."""

from __future__ import annotations

import numpy as np

from stereovo.camera import StereoCamera


CAM = StereoCamera(width=320, height=240, cx=160.0, cy=120.0)


def texture_image(seed=0, shape=(240, 320)):
    return np.random.default_rng(seed).integers(0, 256, shape, dtype=np.uint8)
