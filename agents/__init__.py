"""vo-gym's learned samplers: networks, trainers, checkpoints and :class:`LearnedEstimator`.

``import agents`` stays light (no torch): the exports below load on first use.

    from agents import LearnedEstimator

    estimator = LearnedEstimator("adaptive-pg-prior")          # or "ngransac-supervised", a .pt path
    estimate = estimator.estimate(prev, curr, camera, scores)  # (N, 4) pixels, a StereoCamera, (N,)
"""

from __future__ import annotations

import importlib
from typing import Any

_LAZY = {
    "LearnedEstimator": "agents.estimator",
    "LearnedMotionEstimate": "agents.estimator",
    "load_sampler": "agents.samplers",
    "SHIPPED_SAMPLERS": "agents.checkpoint",
    "SHIPPED_IN_FRAME_SAMPLERS": "agents.checkpoint",
    "CheckpointError": "agents.checkpoint",
}

__all__ = list(_LAZY)


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'agents' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))
