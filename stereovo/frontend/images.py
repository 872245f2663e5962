"""Checks of the images a user passes to the front end: grey ``uint8`` arrays of one size.

A wrong type, dtype or shape, a colour image or images of different sizes raise ``ValueError``
naming the argument; an image the front end cannot find features in (blank, or smaller than the
detector's border) is not an error: :func:`blank_reason` says why, and the caller returns an
empty result carrying that reason.
"""

from __future__ import annotations

from typing import Any

import numpy as np

MIN_IMAGE_SIDE = 64
"""Images narrower or lower than this (px) hold no features: ORB's border alone is 31 px."""


def grey_image(image: Any, name: str) -> np.ndarray:
    """``image`` as a C-contiguous ``(H, W)`` uint8 array, or ``ValueError`` naming ``name``.

    A ``(H, W, 1)`` array is accepted as grey; ``(H, W, 3)`` or ``(H, W, 4)`` is refused as a colour
    image (convert it first, e.g. ``cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)``: the front end does not
    guess a channel order).
    """
    if not isinstance(image, np.ndarray):
        raise ValueError(f"{name} must be a numpy array (a grey uint8 image), got {type(image).__name__}")
    if image.ndim == 3 and image.shape[2] in (3, 4):
        raise ValueError(
            f"{name} is a colour image of shape {image.shape}: pass a grey (H, W) uint8 image "
            "(e.g. cv2.cvtColor(image, cv2.COLOR_BGR2GRAY))"
        )
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[:, :, 0]
    if image.ndim != 2:
        raise ValueError(f"{name} must be a grey image of shape (H, W), got shape {image.shape}")
    if image.dtype != np.uint8:
        raise ValueError(
            f"{name} must have dtype uint8 (grey levels 0-255), got {image.dtype}"
            + (" (scale float images in [0, 1] by 255 and round)" if image.dtype.kind == "f" else "")
        )
    return np.ascontiguousarray(image)


def same_size(images: dict[str, np.ndarray], camera: Any) -> None:
    """``ValueError`` unless every image has the camera's size ``(height, width)``."""
    expected = (int(camera.height), int(camera.width))
    for name, image in images.items():
        if image.shape != expected:
            raise ValueError(
                f"{name} has shape {image.shape} but the camera's images are (height, width) = {expected}: "
                "images and camera must match (give the StereoCamera width= and height= of the images)"
            )


def blank_reason(image: np.ndarray, name: str) -> str:
    """Why ``image`` can hold no features (``""`` when it may)."""
    h, w = image.shape
    if h < MIN_IMAGE_SIDE or w < MIN_IMAGE_SIDE:
        return f"{name} is {w}x{h} px, smaller than {MIN_IMAGE_SIDE} px on a side: no room for features"
    low, high = int(image.min()), int(image.max())
    if low == high:
        return f"{name} is blank (every pixel is {low}): no features"
    return ""
