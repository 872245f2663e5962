"""stereovo.sequences.base: the simulator's adapter gives the same frames."""

from __future__ import annotations

import numpy as np
import pytest

from stereovo.sequences import FrameSequence, SimulatedSequence, as_frame_sequence
from stereovo.simulation import Sequence, SimulationConfig


pytest.importorskip("cv2", reason="the image front end needs OpenCV: pip install 'vo-gym[images]'")


def test_the_simulators_adapter_gives_the_same_frames():
    config = SimulationConfig(n_frames=2, n_correspondences=20)
    seq = Sequence(config, 9)
    adapted = as_frame_sequence(seq)
    assert isinstance(adapted, SimulatedSequence) and isinstance(adapted, FrameSequence)
    assert adapted.camera == config.camera and len(adapted) == 2
    for a, b in zip(adapted, Sequence(config, 9)):
        assert np.array_equal(a.prev, b.prev) and np.array_equal(a.scores, b.scores)
    with pytest.raises(TypeError, match="not a frame sequence"):
        as_frame_sequence([1, 2])
