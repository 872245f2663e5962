"""Camera motion of the simulator: the body-frame velocity process and its presets.

A :class:`MotionPreset` is the stationary law and correlation time of a
mean-reverting AR(1) twist (the exact discretisation of an Ornstein-Uhlenbeck
process); :data:`PRESETS` names the two styles, a road vehicle and a free 6-DoF mover.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from scipy.signal import lfilter


@dataclass(frozen=True)
class MotionPreset:
    """Stationary statistics of the body-frame velocity process of one motion style.

    The twist ``xi = (v, w)`` (linear m/frame along camera x, y, z; angular
    rad/frame about camera x, y, z) evolves as
    ``xi_k - mean = a (xi_{k-1} - mean) + sqrt(1 - a^2) std * eta_k`` with
    ``a = exp(-reversion)`` and ``eta_k ~ N(0, I)``: its stationary law is
    ``N(mean, diag(std^2))`` and its correlation time ``1 / reversion`` frames.

    Args:
        speed: mean forward speed along the camera +z axis (m/frame).
        linear_std: stationary std of the linear velocity along x, y, z (m/frame).
        angular_std: stationary std of the angular velocity about x, y, z (rad/frame);
            y points down, so yaw is about y.
        reversion: mean-reversion rate per frame (> 0); large values give white noise.
        description: one line for humans.
    """

    speed: float
    linear_std: tuple[float, float, float]
    angular_std: tuple[float, float, float]
    reversion: float
    description: str = ""

    def __post_init__(self) -> None:
        if not (math.isfinite(self.speed) and self.speed >= 0):
            raise ValueError(f"MotionPreset.speed must be a finite number >= 0, got {self.speed!r}")
        for name in ("linear_std", "angular_std"):
            value = tuple(float(x) for x in getattr(self, name))
            if len(value) != 3 or not all(math.isfinite(x) and x >= 0 for x in value):
                raise ValueError(f"MotionPreset.{name} must be 3 finite numbers >= 0, got {getattr(self, name)!r}")
            object.__setattr__(self, name, value)
        if not (math.isfinite(self.reversion) and self.reversion > 0):
            raise ValueError(f"MotionPreset.reversion must be a finite number > 0, got {self.reversion!r}")

    @property
    def mean(self) -> np.ndarray:
        """Mean twist ``(6,)``: forward at ``speed``, no rotation."""
        return np.array([0.0, 0.0, self.speed, 0.0, 0.0, 0.0])

    @property
    def std(self) -> np.ndarray:
        """Stationary std ``(6,)`` of the twist, ordered like the twist ``(v, w)``."""
        return np.array(self.linear_std + self.angular_std)

    def with_speed(self, speed: float) -> MotionPreset:
        """The same style at another mean speed (m/frame); linear stds scale along."""
        scale = speed / self.speed if self.speed > 0 else 0.0
        return replace(self, speed=float(speed), linear_std=tuple(s * scale for s in self.linear_std))

    def sample_twist(self, rng: np.random.Generator) -> np.ndarray:
        """One twist ``(6,)`` from the stationary law: the process at a random time."""
        return self.mean + self.std * rng.standard_normal(6)

    def sample_twists(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """``n`` consecutive twists ``(n, 6)`` of the process, started in its stationary law."""
        a = math.exp(-self.reversion)
        start = self.std * rng.standard_normal(6)
        innovations = self.std * math.sqrt(1.0 - a * a) * rng.standard_normal((n, 6))
        # lfilter runs the AR(1) recursion in C; zi carries the start state.
        deviation = lfilter([1.0], [1.0, -a], innovations, axis=0, zi=(a * start)[None, :])[0]
        return self.mean + deviation


PRESETS: dict[str, MotionPreset] = {
    "car": MotionPreset(
        speed=1.0, linear_std=(0.02, 0.01, 0.15), angular_std=(0.001, 0.02, 0.001), reversion=0.1,
        description="road vehicle: forward ~1 m/frame, yaw-dominant turns, small pitch/roll",
    ),
    "free": MotionPreset(
        speed=0.3, linear_std=(0.1, 0.1, 0.1), angular_std=(0.03, 0.03, 0.03), reversion=0.2,
        description="hand-held / drone: 6-DoF, ~0.3 m/frame, a few degrees per frame about all axes",
    ),
}
"""Motion presets by name; ``SimulationConfig.preset`` picks one."""
