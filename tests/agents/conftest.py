"""Fixtures of the agents' tests."""

from __future__ import annotations

import pytest


@pytest.fixture
def one_torch_thread():
    """Torch on one thread for the test (OpenMP threads contend badly on small shared machines)."""
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)
