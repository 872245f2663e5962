"""The simulator's entry points: a standalone frame pair, or a lazily simulated trajectory.

:func:`simulate_frame` draws one step of the motion at a random state;
:class:`Sequence` draws a whole trajectory up front and each frame pair on demand
from its own child seed, so frames come out the same in any order of access.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from stereovo.geometry import make_transform, pose_update, random_rotation, se3_exp, so3_exp
from stereovo.options import is_integer, value_repr
from stereovo.seeding import generator_from_seed_words, seed_words, seeded_generators
from stereovo.simulation.config import SimulationConfig
from stereovo.simulation.frame import Frame
from stereovo.simulation.pair import simulate_pair

_SEQUENCE_NAMESPACE = 0x566F  # keeps Sequence's child seeds apart from a user's own spawn() children


def _check_config(config: object) -> None:
    if not isinstance(config, SimulationConfig):
        raise TypeError(f"config must be a SimulationConfig, got {type(config).__name__}")


def _is_seed(value: object) -> bool:
    """An integer seed >= 0 (not a bool: ``True`` is no seed, as for the estimator)."""
    return is_integer(value) and value >= 0


def simulate_frame(config: SimulationConfig, rng: np.random.Generator | int | None = None) -> Frame:
    """A standalone frame pair: one step of the preset's motion at a random state, a fresh world patch.

    The pose of frame k-1 is random (a random heading and position for ``car``,
    a random orientation for ``free``); frame k follows from one twist drawn
    from the stationary law of the preset's velocity process.

    Args:
        config: the simulation settings.
        rng: a numpy Generator, an int seed >= 0 (not a bool), a SeedSequence, or None for fresh
            entropy (as :func:`numpy.random.default_rng` takes them).

    Returns:
        A :class:`Frame` with ``index == 1``.

    Raises:
        TypeError: ``config`` is no :class:`SimulationConfig`.
        ValueError: ``rng`` is none of the above, naming it and the value.
        InfeasibleSettingsError: the settings leave this draw without a frame (see
            :class:`SimulationConfig`).
    """
    _check_config(config)
    if not (rng is None or _is_seed(rng) or isinstance(rng, (np.random.Generator, np.random.SeedSequence))):
        raise ValueError(f"rng must be a numpy.random.Generator, a SeedSequence, an integer seed >= 0 or None, "
                         f"got {value_repr(rng)}")
    rng = np.random.default_rng(rng)
    if config.preset == "car":
        orientation = so3_exp(np.array([0.0, rng.uniform(-np.pi, np.pi), 0.0]))
        position = np.array([rng.uniform(-100, 100), 0.0, rng.uniform(-100, 100)])
    else:
        orientation = random_rotation(rng)
        position = rng.uniform(-100, 100, 3)
    pose_prev = make_transform(orientation, position)
    rotation, translation = se3_exp(-config.motion.sample_twist(rng))
    pose_curr = pose_update(pose_prev, rotation, translation)
    return simulate_pair(config, pose_prev, pose_curr, 1, rng)


class Sequence:
    """A lazily simulated trajectory of ``config.n_frames`` frame pairs.

    The trajectory (cheap) is drawn in ``__init__``; frame k is generated on
    demand from its own seed, so ``frame(k)`` gives the same result in any
    order of access, and the same seed gives bit-identical frames.

    Frames whose settings leave the draw without a frame raise
    :class:`~stereovo.simulation.config.InfeasibleSettingsError` from :meth:`frame`.

    Attributes:
        config: the simulation settings.
        seed: the seed as given (an int >= 0, not a bool; a SeedSequence; or None). Anything else
            is a ValueError naming ``seed`` and the value.
        true_poses: ``(n_frames + 1, 4, 4)`` read-only camera-to-world poses,
            ``true_poses[0]`` the identity.
    """

    def __init__(self, config: SimulationConfig, seed: int | np.random.SeedSequence | None = None) -> None:
        _check_config(config)
        if not (seed is None or _is_seed(seed) or isinstance(seed, np.random.SeedSequence)):
            raise ValueError(f"seed must be an integer >= 0, a numpy.random.SeedSequence or None, got {value_repr(seed)}")
        self.config = config
        self.seed = seed
        self._root = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
        root = self._root
        # every child's seed words at once (one compiled hash instead of one call a frame); None
        # where numpy's own seeding must run (entropy outside the fast path)
        self._seed_words = seed_words(
            root.entropy, [(*root.spawn_key, _SEQUENCE_NAMESPACE, k) for k in range(config.n_frames + 1)],
            root.pool_size,
        )
        twists = config.motion.sample_twists(self._child_rng(0), config.n_frames)
        rotations, translations = se3_exp(-twists)
        poses = np.empty((config.n_frames + 1, 4, 4))
        poses[0] = np.eye(4)
        for k in range(config.n_frames):
            poses[k + 1] = pose_update(poses[k], rotations[k], translations[k])
        poses.setflags(write=False)
        self.true_poses = poses

    @property
    def seed_sequence(self) -> np.random.SeedSequence:
        """The root SeedSequence; its entropy reproduces a sequence made with ``seed=None``."""
        return self._root

    def _child_rng(self, k: int) -> np.random.Generator:
        """The generator of ``SeedSequence(root.entropy, spawn_key=(*root.spawn_key, namespace, k))``."""
        if self._seed_words is not None:
            return generator_from_seed_words(self._seed_words[k])
        root = self._root
        return seeded_generators(root.entropy, [(*root.spawn_key, _SEQUENCE_NAMESPACE, k)], root.pool_size)[0]

    def __len__(self) -> int:
        return self.config.n_frames

    def __iter__(self) -> Iterator[Frame]:
        for k in range(1, self.config.n_frames + 1):
            yield self.frame(k)

    def frame(self, k: int) -> Frame:
        """Frame pair ``(k-1, k)`` for ``1 <= k <= n_frames``.

        Raises:
            IndexError: if k is out of range.
        """
        if not is_integer(k) or not 1 <= k <= self.config.n_frames:
            raise IndexError(f"frame index must be an integer in [1, {self.config.n_frames}], got {k!r}")
        k = int(k)
        rng = self._child_rng(k)
        return simulate_pair(self.config, self.true_poses[k - 1], self.true_poses[k], k, rng)

    def __repr__(self) -> str:
        return f"Sequence(n_frames={len(self)}, preset={self.config.preset!r}, seed={self.seed!r})"
