"""JPEG files for the loader's tests, written by Pillow: baseline or progressive, with an EXIF block
that holds a thumbnail (a JPEG, with its own end-of-image marker, inside the APP1 segment)."""

from __future__ import annotations

import io
import struct

import numpy as np


def jpeg_bytes(image: np.ndarray, progressive: bool = False, exif: bytes | None = None, quality: int = 90) -> bytes:
    """``image`` (``(H, W)`` uint8 grey) as a JPEG file's bytes; ``exif``: APP1's payload (see
    :func:`exif_with_thumbnail`)."""
    from PIL import Image

    buffer = io.BytesIO()
    options = {"exif": exif} if exif is not None else {}
    Image.fromarray(image).save(buffer, "JPEG", quality=quality, progressive=progressive, **options)
    return buffer.getvalue()


def exif_with_thumbnail(thumbnail: bytes) -> bytes:
    """An EXIF block (APP1's payload) as cameras write one: ``Exif\\0\\0``, a big-endian TIFF header, an
    empty IFD0 and an IFD1 whose JPEGInterchangeFormat (0x0201) and ...Length (0x0202) point at
    ``thumbnail``, which follows."""
    ifd1 = 8 + 2 + 4  # after the TIFF header and the empty IFD0 (its count, its next-IFD offset)
    start = ifd1 + 2 + 2 * 12 + 4  # after IFD1's count, 2 entries and its next-IFD offset
    tiff = (b"MM\x00\x2a" + struct.pack(">I", 8) + struct.pack(">HI", 0, ifd1) + struct.pack(">H", 2)
            + struct.pack(">HHII", 0x0201, 4, 1, start) + struct.pack(">HHII", 0x0202, 4, 1, len(thumbnail))
            + struct.pack(">I", 0) + thumbnail)
    return b"Exif\x00\x00" + tiff


def smooth_noise(height: int, width: int, seed: int = 0) -> np.ndarray:
    """A ``(height, width)`` uint8 image of blurred noise: a scan of some kilobytes."""
    import cv2

    rng = np.random.default_rng(seed)
    return cv2.GaussianBlur(rng.integers(0, 256, (height, width), np.uint8), (5, 5), 2)
