"""stereovo.sequences.jpeg: a JPEG is complete when its segments and scans reach its end-of-image
marker; every cut is truncated, bytes after the marker are not read, garbage is refused in time."""

from __future__ import annotations

import io
import re
import struct

import numpy as np
import pytest

from stereovo.sequences.jpeg import MAX_SEGMENTS, jpeg_defect
from tests.support.jpegs import exif_with_thumbnail, jpeg_bytes, smooth_noise


pytest.importorskip("cv2", reason="the test images are blurred with OpenCV: pip install 'vo-gym[images]'")


def defect(data: bytes) -> str | None:
    return jpeg_defect(io.BytesIO(data))


def _scan_only(entropy: bytes, fill: int = 0) -> bytes:
    """A file of the walker's structure alone (no decoder reads it): SOI, one SOS segment, ``entropy``,
    then ``fill`` fill bytes and EOI."""
    return b"\xff\xd8" + b"\xff\xda" + struct.pack(">H", 8) + bytes(6) + entropy + b"\xff" * fill + b"\xff\xd9"


@pytest.fixture(scope="module")
def jpegs():
    """Pillow's baseline and progressive (6 scans) JPEGs, OpenCV's with restart markers, and one with an
    EXIF thumbnail: each a complete file."""
    import cv2

    image = smooth_noise(96, 128)
    files = {"baseline": jpeg_bytes(image), "progressive": jpeg_bytes(image, progressive=True),
             "restart markers": cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_RST_INTERVAL, 2])[1].tobytes(),
             "EXIF thumbnail": jpeg_bytes(image, exif=exif_with_thumbnail(jpeg_bytes(smooth_noise(16, 16, 1))))}
    assert files["progressive"].count(b"\xff\xda") > 1 and b"\xff\xd0" in files["restart markers"]
    return files


@pytest.mark.parametrize("kind", ["baseline", "progressive", "restart markers", "EXIF thumbnail"])
def test_a_complete_jpeg_passes_and_every_cut_of_it_is_truncated(jpegs, kind):
    data = jpegs[kind]
    assert defect(data) is None
    for cut in range(2, len(data)):
        assert defect(data[:cut]).startswith(f"a truncated JPEG (its {cut} bytes end "), cut


def test_bytes_after_the_end_of_image_marker_are_not_read(jpegs):
    """Cameras and tools append padding, metadata or (MPO) more images: the file is complete at its marker."""
    tail = np.random.default_rng(3).integers(0, 256, 1024, np.uint8).tobytes()
    for data in jpegs.values():
        assert defect(data + tail) is None and defect(data + b"\xff\xd8\xff\xe0" + tail) is None


def test_an_exif_thumbnails_end_marker_does_not_end_the_file(jpegs):
    """The thumbnail inside APP1 ends with FF D9 of its own: a file cut just after it, or in its main scan,
    is truncated (APP1 is skipped by its length)."""
    data = jpegs["EXIF thumbnail"]
    thumbnail = jpeg_bytes(smooth_noise(16, 16, 1))
    end = data.index(thumbnail) + len(thumbnail)
    assert defect(data[:end]) == (f"a truncated JPEG (its {end} bytes end after the segment of marker FF E1 at "
                                  "byte 20, before the end-of-image marker FF D9)")
    assert defect(data[:end - 1]).startswith(f"a truncated JPEG (its {end - 1} bytes end inside the segment of "
                                             "marker FF E1 at byte 20, which declares")
    middle = (end + len(data)) // 2
    assert defect(data[:middle]) == (f"a truncated JPEG (its {middle} bytes end in the entropy-coded data of scan 1, "
                                     "before the end-of-image marker FF D9)")


@pytest.mark.parametrize("length, message", [
    (0, r"a damaged JPEG \(the segment of marker FF C4 declares a length of 0; a length counts its own 2 bytes, "
        r"at byte \d+\)"),
    (1, r"a damaged JPEG \(the segment of marker FF C4 declares a length of 1;"),
    (0xFFFF, r"a truncated JPEG \(its \d+ bytes end inside the segment of marker FF C4 at byte \d+, which declares "
             r"65535 bytes,"),
    (3, r"a damaged JPEG \(byte 0x[0-9A-F]{2} where a marker FF xx must begin, at byte \d+\)"),
])
def test_garbage_in_a_segment_length_is_refused(jpegs, length, message):
    """The length of the Huffman table after the progressive file's first scan (a segment Pillow does
    not read) set to garbage: refused as damaged or truncated, never accepted, never an exception."""
    data = jpegs["progressive"]
    table = data.index(b"\xff\xc4", data.index(b"\xff\xda") + 2)
    assert data[table + 4] != 0xFF  # (a 3-byte segment ends inside the table, on a byte that is no marker)
    damaged = data[:table + 2] + struct.pack(">H", length) + data[table + 4:]
    assert re.match(message, defect(damaged)), defect(damaged)


def test_random_damage_to_the_headers_gives_a_verdict(jpegs):
    """Bytes of the marker segments overwritten at random: every file gets a verdict (None or a reason)."""
    rng = np.random.default_rng(7)
    data = jpegs["progressive"]
    verdicts = set()
    for _ in range(500):
        damaged = bytearray(data)
        for at in rng.integers(2, data.index(b"\xff\xda") + 10, 3):
            damaged[at] = rng.integers(0, 256)
        verdict = defect(bytes(damaged))
        assert verdict is None or verdict.startswith(("a truncated JPEG (", "a damaged JPEG ("))
        verdicts.add(verdict.split(" (")[0] if verdict else None)
    assert verdicts == {None, "a truncated JPEG", "a damaged JPEG"}


@pytest.mark.parametrize("n", [1, 4094, 4095, 4096, 4097, 12286, 12287, 12288, 12289])
def test_markers_and_fill_across_the_read_windows(n):
    """The walker reads 4 KiB, then windows doubling to 1 MiB: a scan, or a run of fill bytes, ending on
    either side of a window's edge ends where it ends."""
    entropy = bytes([0x12, 0xFF, 0x00, 0xFF, 0xD3]) * (n // 5) + b"\x34" * (n % 5)
    for fill in (0, n):
        data = _scan_only(entropy, fill)
        assert defect(data) is None
        assert defect(data[:-1]).startswith(f"a truncated JPEG (its {len(data) - 1} bytes end in the entropy-coded")
    assert defect(b"\xff\xd8" + b"\xff" * n + b"\xfe\x00\x02" + _scan_only(entropy)[2:]) is None


def test_structures_no_decoder_follows_are_damaged():
    scan = _scan_only(b"\x12\x34")
    assert defect(b"\xff\xd9" + scan) == "a damaged JPEG (it does not begin with the start-of-image marker FF D8)"
    assert defect(b"\xff\xd8\xff\xd9") == ("a damaged JPEG (its end-of-image marker comes before any scan, at "
                                           "byte 2)")
    assert defect(scan[:-2] + scan) == "a damaged JPEG (a second start-of-image marker FF D8, at byte 14)"
    many = b"\xff\xd8" + b"\xff\xfe\x00\x02" * (MAX_SEGMENTS + 1) + scan[2:]
    assert defect(many) == (f"a damaged JPEG (more than {MAX_SEGMENTS:,} marker segments before its end-of-image "
                            f"marker, at byte {2 + 4 * MAX_SEGMENTS})")
    assert defect(b"\xff\xd8" + b"\xff\xfe\x00\x02" * (MAX_SEGMENTS - 2) + scan[2:]) is None
