""":func:`jpeg_defect`: whether a JPEG file is complete, from its structure (ITU-T T.81, Annex B).

OpenCV decodes a truncated JPEG with its missing part grey, without an error, so a loader must tell
a truncated file itself. Its last bytes cannot: cameras and tools append data after the end-of-image
marker (padding, metadata, an MPO's further images), and an EXIF thumbnail inside APP1 holds an
end-of-image marker of its own. So the file is walked as a decoder reads it: marker segments, each
skipped by its length, up to a start-of-scan; then the scan's entropy-coded data up to the next
marker. The file is complete when that walk reaches the end-of-image marker (FF D9); nothing after it
is read.

A marker is ``FF xx``, any number of fill bytes ``FF`` before it. Inside entropy-coded data ``FF 00``
is a stuffed ``FF`` byte and ``FF D0`` .. ``FF D7`` are restart markers: neither ends a scan.
"""

from __future__ import annotations

import io
from collections.abc import Callable
from typing import BinaryIO

import numpy as np

SOI, EOI, SOS, TEM = 0xD8, 0xD9, 0xDA, 0x01
"""The markers' second bytes: start and end of image, start of scan, and TEM (no length, as RST0-7)."""

_FIRST, _CHUNK = 1 << 12, 1 << 20
"""The bytes read, and searched for a marker at once, at first and at most (B), the window doubling in
between: a file may carry gigabytes after its end-of-image marker, or be gigabytes of scan, and is
never read whole; most searches end within the first few bytes (fill, a short scan)."""

MAX_SEGMENTS = 10_000
"""The most marker segments (scans included) walked before the end-of-image marker. Each is a step of
Python: a hostile file of millions of 4-byte segments would take minutes. Real files hold tens (a
progressive JPEG about 20 scans and tables)."""


def jpeg_defect(handle: BinaryIO) -> str | None:
    """Why the JPEG file open as ``handle`` (binary, seekable) is not complete, or None when it is.

    Returns:
        ``"a truncated JPEG (its N bytes end WHERE, before the end-of-image marker FF D9)"``, or
        ``"a damaged JPEG (WHAT, at byte N)"`` for a structure no decoder could follow (a segment
        length under 2, a byte other than a marker where a marker must be, a second start-of-image,
        no scan, more than :data:`MAX_SEGMENTS` segments); byte offsets count from the file's start.
    """
    size = handle.seek(0, io.SEEK_END)

    def read(pos: int, n: int) -> bytes:
        handle.seek(pos)
        return handle.read(n)

    def truncated(where: str) -> str:
        return f"a truncated JPEG (its {size} bytes end {where}, before the end-of-image marker FF D9)"

    if read(0, 2) != bytes((0xFF, SOI)):
        return "a damaged JPEG (it does not begin with the start-of-image marker FF D8)"
    pos, scans, in_scan, after = 2, 0, False, "after the start-of-image marker"
    for _ in range(MAX_SEGMENTS):
        if in_scan:
            found = _next_marker(read, pos)
            if found is None:
                return truncated(f"in the entropy-coded data of scan {scans}")
            pos = found
        else:
            first = read(pos, 1)
            if not first:
                return truncated(after)
            if first[0] != 0xFF:
                return f"a damaged JPEG (byte 0x{first[0]:02X} where a marker FF xx must begin, at byte {pos})"
            pos = _last_fill(read, pos)
        second = read(pos + 1, 1)
        if not second:
            return truncated(f"in the marker at byte {pos}")
        marker = second[0]
        if marker == EOI:
            return None if scans else f"a damaged JPEG (its end-of-image marker comes before any scan, at byte {pos})"
        if marker == SOI:
            return f"a damaged JPEG (a second start-of-image marker FF D8, at byte {pos})"
        if marker == TEM or 0xD0 <= marker <= 0xD7:  # markers without a length
            pos, in_scan, after = pos + 2, False, f"after the marker FF {marker:02X} at byte {pos}"
            continue
        head = read(pos + 2, 2)
        if len(head) < 2:
            return truncated(f"in the length of the segment of marker FF {marker:02X} at byte {pos}")
        length = int.from_bytes(head, "big")
        if length < 2:  # the length counts its own two bytes: less would step backwards, or nowhere
            return (f"a damaged JPEG (the segment of marker FF {marker:02X} declares a length of {length}; a "
                    f"length counts its own 2 bytes, at byte {pos})")
        if pos + 2 + length > size:
            return truncated(f"inside the segment of marker FF {marker:02X} at byte {pos}, which declares "
                             f"{length} bytes")
        after = f"after the segment of marker FF {marker:02X} at byte {pos}"
        pos, in_scan = pos + 2 + length, marker == SOS
        scans += in_scan
    return f"a damaged JPEG (more than {MAX_SEGMENTS:,} marker segments before its end-of-image marker, at byte {pos})"


def _next_marker(read: Callable[[int, int], bytes], pos: int) -> int | None:
    """The offset of the ``FF`` of the first marker at or after ``pos`` in entropy-coded data (not
    ``FF 00``, ``FF D0`` .. ``FF D7`` or a fill ``FF FF``), or None when the file ends first."""
    window = _FIRST
    while True:
        chunk = np.frombuffer(read(pos, window + 1), np.uint8)  # one byte more: a pair across windows
        if chunk.size < 2:
            return None
        ff = np.flatnonzero(chunk[:-1] == 0xFF)
        after = chunk[ff + 1]
        ends = ff[(after != 0x00) & (after != 0xFF) & ((after < 0xD0) | (after > 0xD7))]
        if ends.size:
            return pos + int(ends[0])
        pos, window = pos + chunk.size - 1, min(2 * window, _CHUNK)


def _last_fill(read: Callable[[int, int], bytes], pos: int) -> int:
    """The offset of the last ``FF`` of the run of ``FF`` bytes at ``pos``: the one the marker's byte
    follows (the others are fill); the file's last byte when the run reaches the end."""
    window = _FIRST
    while True:
        chunk = np.frombuffer(read(pos, window), np.uint8)
        other = np.flatnonzero(chunk != 0xFF)
        if other.size:
            return pos + int(other[0]) - 1
        if chunk.size < window:
            return pos + chunk.size - 1
        pos, window = pos + chunk.size, min(2 * window, _CHUNK)
