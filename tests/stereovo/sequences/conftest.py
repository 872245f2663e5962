"""Fixtures of the sequence tests."""

from __future__ import annotations

import pytest

from tests.support.images import rendered


@pytest.fixture(scope="module")
def short():
    """A 3-frame rendered car sequence (VGA), closed after the module's tests."""
    sequence = rendered(preset="car", n_frames=3, resolution="vga", seed=21)
    yield sequence
    sequence.close()
