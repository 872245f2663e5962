"""Sampling policies behind one interface: observation in, per-slot action out, batched.

A policy maps the environment's observation ``{"features": (N_max, F) or
(B, N_max, F), "mask": (N_max,) or (B, N_max)}`` to one value per slot: logits
of guided-sampling weights (``StereoVO-v0``) or scores whose ranking is the
PROSAC order (``StereoVOProsac-v0``). Both envs read "higher = more trusted",
so one policy serves both.

Heuristics read a single feature column; the oracle reads ground-truth labels
and is an upper bound for reports only, never a default.
"""

from __future__ import annotations

from typing import Callable, Protocol

import numpy as np

from vo_gym.features import feature_index

# Logits stay inside the environment's action bounds.
LOGIT_BOUND = 10.0


class Policy(Protocol):
    name: str

    def act(self, observation: dict) -> np.ndarray:
        """Per-slot actions ``(N_max,)`` or ``(B, N_max)`` float32, padded slots set to -LOGIT_BOUND."""
        ...


def _finish(values: np.ndarray, mask: np.ndarray) -> np.ndarray:
    out = np.clip(values, -LOGIT_BOUND, LOGIT_BOUND).astype(np.float32)
    return np.where(np.asarray(mask, dtype=bool), out, np.float32(-LOGIT_BOUND))


class FeaturePolicy:
    """Logits from one feature column: ``scale * transform(column)``."""

    def __init__(self, name: str, column: str, transform: Callable[[np.ndarray], np.ndarray], scale: float = 1.0):
        self.name = name
        self.column = feature_index(column)
        self.transform = transform
        self.scale = scale

    def act(self, observation: dict) -> np.ndarray:
        column = np.asarray(observation["features"])[..., self.column].astype(np.float64)
        return _finish(self.scale * self.transform(column), observation["mask"])


class UniformPolicy:
    """Every correspondence equally likely: plain RANSAC sampling."""

    name = "uniform"

    def act(self, observation: dict) -> np.ndarray:
        return _finish(np.zeros(np.asarray(observation["mask"]).shape), observation["mask"])


class ConstantVelocityPolicy:
    """Trust matches that the previous frame's motion predicts well; uniform when it is unknown."""

    name = "constant-velocity"

    def __init__(self, scale: float = 4.0) -> None:
        self.scale = scale
        self.residual = feature_index("cv_residual")
        self.available = feature_index("cv_available")

    def act(self, observation: dict) -> np.ndarray:
        f = np.asarray(observation["features"], dtype=np.float64)
        logits = -self.scale * f[..., self.residual] * f[..., self.available]
        return _finish(logits, observation["mask"])


class OraclePolicy:
    """Upper bound for reports only: reads the ground-truth labels of the current frame.

    Args:
        labels_fn: returns the ``(N,)`` inlier labels of the frame behind the current observation
            (e.g. from the environment's hidden state); never available to a real agent.
    """

    name = "oracle"

    def __init__(self, labels_fn: Callable[[], np.ndarray]) -> None:
        self.labels_fn = labels_fn

    def act(self, observation: dict) -> np.ndarray:
        mask = np.asarray(observation["mask"], dtype=bool)
        labels = np.asarray(self.labels_fn(), dtype=bool)
        logits = np.full(mask.shape, -LOGIT_BOUND)
        logits[: labels.shape[0]] = np.where(labels, LOGIT_BOUND, -LOGIT_BOUND)
        return _finish(logits, mask)


def _log(x: np.ndarray) -> np.ndarray:
    return np.log(np.clip(x, 1e-6, None))


HEURISTICS: dict[str, Callable[[], Policy]] = {
    "uniform": UniformPolicy,
    "match-score": lambda: FeaturePolicy("match-score", "match_score", _log),
    "consistency": lambda: FeaturePolicy("consistency", "rigid_consistency", _log, scale=2.0),
    "constant-velocity": ConstantVelocityPolicy,
}


def make_heuristic(name: str) -> Policy:
    """A heuristic policy by name (see ``HEURISTICS``); the oracle needs labels and is built directly."""
    if name not in HEURISTICS:
        raise ValueError(f"unknown heuristic {name!r}; available: {', '.join(HEURISTICS)} (and 'oracle' in reports)")
    return HEURISTICS[name]()
