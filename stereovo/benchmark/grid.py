"""The benchmark grid and its seeding: which frames a run simulates.

A :class:`GridCell` is one simulator setting (contamination epsilon, pixel noise sigma,
match-score AUC, number of correspondences N, outlier kind); a :class:`BenchmarkGrid` is the
product of its axes times ``frames_per_cell`` repeats, and :meth:`BenchmarkGrid.trials` lists
its :class:`Trial` s. :data:`DEFAULT_GRID` is the README's main job, :data:`FULL_GRID` the
issue's whole grid.

Seeding (same seed, same CSV): a trial's frame generator is
``SeedSequence(seed, spawn_key=(FRAME, epsilon, N, outlier kind, repeat))``
and each estimator's generator adds the estimator's name. Noise sigma and
AUC are left out of the key on purpose: cells that differ only in them see the
same landmarks, outliers and standard-normal noise draws (the simulator keeps
those streams independent), so those axes are compared on common random
numbers. Keys use the cell's *values*, not its position in the grid, so a cell
gives the same frames in the default grid, the full grid or a custom one.
"""

from __future__ import annotations

import itertools
import zlib
from dataclasses import dataclass, replace
from typing import Any, Iterable

import numpy as np

from stereovo.options import Integer
from stereovo.simulation import Frame, SimulationConfig, simulate_frame

OUTLIER_MIXES: dict[str, tuple[float, float, float] | None] = {
    "mix": SimulationConfig().outlier_mix,  # the simulator's default blend
    "random": (1.0, 0.0, 0.0),
    "stereo": (0.0, 1.0, 0.0),
    "moving": (0.0, 0.0, 1.0),
    "hostile": None,  # the simulator's hostile preset: its own mix and Student-t pixel noise
}
"""Outlier kinds of the grid -> ``SimulationConfig.outlier_mix`` weights (random, stereo, moving
object); None: the simulator's ``outliers="hostile"`` preset (independent left/right mismatches,
duplicates, far clutter, repetitive texture and a few random and stereo mismatches, with Student-t
pixel noise of scale sigma), match errors the default grid never makes."""


@dataclass(frozen=True)
class GridCell:
    """One simulator setting of the benchmark grid."""

    epsilon: float
    noise_sigma: float
    score_auc: float
    n: int
    outlier_kind: str = "mix"
    preset: str = "car"

    def config(self) -> SimulationConfig:
        """The simulator config of this cell (validated by :class:`SimulationConfig`)."""
        if self.outlier_kind not in OUTLIER_MIXES:
            raise ValueError(f"unknown outlier kind {self.outlier_kind!r}; known: {', '.join(OUTLIER_MIXES)}")
        mix = OUTLIER_MIXES[self.outlier_kind]
        return SimulationConfig(
            preset=self.preset,
            n_frames=1,
            n_correspondences=int(self.n),
            noise_sigma=float(self.noise_sigma),
            outlier_ratio=float(self.epsilon),
            outlier_mix=mix,
            outliers="default" if mix is not None else "hostile",
            score_auc=float(self.score_auc),
        )

    def as_dict(self) -> dict[str, Any]:
        return {
            "epsilon": float(self.epsilon),
            "noise_sigma": float(self.noise_sigma),
            "score_auc": float(self.score_auc),
            "n": int(self.n),
            "outlier_kind": self.outlier_kind,
        }


@dataclass(frozen=True)
class Trial:
    """One frame of the benchmark: ``repeat``-th frame of cell number ``cell_index``."""

    index: int
    cell_index: int
    cell: GridCell
    repeat: int


@dataclass(frozen=True)
class BenchmarkGrid:
    """The product of the axes, ``frames_per_cell`` frames per cell.

    Args:
        epsilons: contamination ratios in [0, 1).
        noise_sigmas: pixel noise std (px), > 0 (the estimators take it as the sensor spec).
        score_aucs: match-score ROC AUC in [0.5, 1).
        ns: correspondences per frame.
        outlier_kinds: keys of :data:`OUTLIER_MIXES`.
        frames_per_cell: repeats (seeds) per cell.
        preset: motion preset of the simulator.
        max_iterations: the hypothesis cap every classical method runs under
            (None: the estimator core's default).
    """

    epsilons: tuple[float, ...]
    noise_sigmas: tuple[float, ...]
    score_aucs: tuple[float, ...]
    ns: tuple[int, ...]
    outlier_kinds: tuple[str, ...] = ("mix",)
    frames_per_cell: int = 10
    preset: str = "car"
    max_iterations: int | None = None

    def __post_init__(self) -> None:
        for name in ("epsilons", "noise_sigmas", "score_aucs", "ns", "outlier_kinds"):
            values = tuple(getattr(self, name))
            if not values:
                raise ValueError(f"BenchmarkGrid.{name} must not be empty")
            if len(set(values)) != len(values):
                raise ValueError(f"BenchmarkGrid.{name} has repeated values: {values}")
            object.__setattr__(self, name, values)
        object.__setattr__(self, "epsilons", tuple(float(x) for x in self.epsilons))
        object.__setattr__(self, "noise_sigmas", tuple(float(x) for x in self.noise_sigmas))
        object.__setattr__(self, "score_aucs", tuple(float(x) for x in self.score_aucs))
        if any(int(x) != x for x in self.ns):
            raise ValueError(f"BenchmarkGrid.ns must be integers, got {self.ns}")
        object.__setattr__(self, "ns", tuple(int(x) for x in self.ns))
        if any(s <= 0 for s in self.noise_sigmas):
            raise ValueError(f"BenchmarkGrid.noise_sigmas must be > 0 px, got {self.noise_sigmas}")
        unknown = [k for k in self.outlier_kinds if k not in OUTLIER_MIXES]
        if unknown:
            raise ValueError(f"unknown outlier kind(s) {unknown}; known: {', '.join(OUTLIER_MIXES)}")
        Integer(low=1).check("frames_per_cell", self.frames_per_cell, prefix="BenchmarkGrid.")
        Integer(low=1, allow_none=True).check("max_iterations", self.max_iterations, prefix="BenchmarkGrid.")
        for cell in self.cells():  # the simulator validates every value
            cell.config()

    def cells(self) -> list[GridCell]:
        """Cells in a fixed order: epsilon, then sigma, AUC, N, outlier kind."""
        return [
            GridCell(e, s, a, n, k, self.preset)
            for e, s, a, n, k in itertools.product(
                self.epsilons, self.noise_sigmas, self.score_aucs, self.ns, self.outlier_kinds
            )
        ]

    def trials(self) -> list[Trial]:
        """Every (cell, repeat), cell-major."""
        out: list[Trial] = []
        for c, cell in enumerate(self.cells()):
            for r in range(self.frames_per_cell):
                out.append(Trial(len(out), c, cell, r))
        return out

    @property
    def n_cells(self) -> int:
        return (len(self.epsilons) * len(self.noise_sigmas) * len(self.score_aucs)
                * len(self.ns) * len(self.outlier_kinds))

    @property
    def n_trials(self) -> int:
        return self.n_cells * self.frames_per_cell

    def with_axes(self, **changes: Any) -> "BenchmarkGrid":
        """A copy with some fields replaced (None values are ignored)."""
        return replace(self, **{k: v for k, v in changes.items() if v is not None})

    def describe(self) -> str:
        def axis(values: Iterable[Any]) -> str:
            return "{" + ", ".join(f"{v:g}" if isinstance(v, float) else str(v) for v in values) + "}"

        cap = "core default" if self.max_iterations is None else str(self.max_iterations)
        return (
            f"epsilon {axis(self.epsilons)} x sigma {axis(self.noise_sigmas)} px x AUC {axis(self.score_aucs)}"
            f" x N {axis(self.ns)} x outliers {axis(self.outlier_kinds)}: {self.n_cells} cells x"
            f" {self.frames_per_cell} frames = {self.n_trials} frames; preset {self.preset};"
            f" max_iterations {cap}"
        )

    def as_dict(self) -> dict[str, Any]:
        return {
            "epsilons": list(self.epsilons),
            "noise_sigmas": list(self.noise_sigmas),
            "score_aucs": list(self.score_aucs),
            "ns": list(self.ns),
            "outlier_kinds": list(self.outlier_kinds),
            "frames_per_cell": self.frames_per_cell,
            "preset": self.preset,
            "max_iterations": self.max_iterations,
        }


DEFAULT_MAX_ITERATIONS = 2000

DEFAULT_GRID = BenchmarkGrid(
    epsilons=(0.2, 0.5, 0.8),
    noise_sigmas=(0.5,),
    score_aucs=(0.75, 0.9),
    ns=(200, 500),
    outlier_kinds=("mix",),
    frames_per_cell=10,
    max_iterations=DEFAULT_MAX_ITERATIONS,
)
"""The README's main job: about two minutes on two cores with every classical method."""

FULL_GRID = BenchmarkGrid(
    epsilons=(0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9),
    noise_sigmas=(0.25, 0.5, 1.0, 2.0),
    score_aucs=(0.5, 0.75, 0.9),
    ns=(100, 500, 1000),
    outlier_kinds=("mix", "random", "stereo", "moving"),
    frames_per_cell=10,
    max_iterations=None,
)
"""The issue's whole grid (1296 cells): hours, not minutes."""


# --------------------------------------------------------------------------- seeding

_FRAME_TAG = 0x6672616D  # "fram"
_ESTIMATOR_TAG = 0x65737469  # "esti"


def stable_int(text: str) -> int:
    """A process-independent integer for a name (``hash()`` is salted per process)."""
    return zlib.crc32(text.encode("utf-8"))


def quantize(x: float) -> int:
    return int(round(float(x) * 1_000_000))


def _frame_key(cell: GridCell, repeat: int) -> tuple[int, ...]:
    return (quantize(cell.epsilon), int(cell.n), stable_int(cell.outlier_kind), stable_int(cell.preset), int(repeat))


def check_seed(seed: int) -> int:
    return Integer(low=0).check("seed", seed, prefix="")


def frame_seed(seed: int, cell: GridCell, repeat: int) -> np.random.SeedSequence:
    """Seed of the frame of ``(cell, repeat)``; independent of sigma and AUC (common random numbers)."""
    return np.random.SeedSequence(check_seed(seed), spawn_key=(_FRAME_TAG, *_frame_key(cell, repeat)))


def estimator_seed(seed: int, cell: GridCell, repeat: int, name: str) -> np.random.SeedSequence:
    """Seed of estimator ``name`` on the frame of ``(cell, repeat)``."""
    return np.random.SeedSequence(
        check_seed(seed), spawn_key=(_ESTIMATOR_TAG, *_frame_key(cell, repeat), stable_int(name))
    )


def simulate_trial(trial: Trial, seed: int) -> Frame:
    """The frame every estimator sees in ``trial``."""
    return simulate_frame(trial.cell.config(), np.random.default_rng(frame_seed(seed, trial.cell, trial.repeat)))
