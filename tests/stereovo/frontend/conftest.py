"""Fixtures of the front-end tests."""

from __future__ import annotations

import pytest

from tests.support.images import rendered


@pytest.fixture(scope="module")
def street():
    """A 3-frame rendered street (VGA), closed after the module's tests."""
    sequence = rendered(preset="car", n_frames=3, resolution="vga", seed=11)
    yield sequence
    sequence.close()
