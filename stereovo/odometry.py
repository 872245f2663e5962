"""Frame-to-frame stereo visual odometry over a simulated sequence.

Each frame pair goes through the shared estimator core
(:func:`stereovo.estimation.estimate_motion`); the motions are concatenated
into camera-to-world poses with :class:`stereovo.geometry.PoseChain` and
scored against the simulator's truth.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Iterable, Sequence

import numpy as np

from stereovo.estimation import estimate_motion
from stereovo.geometry import PoseChain
from stereovo.metrics import KITTI_LENGTHS, KITTI_STEP, FrameMetrics, TrajectoryMetrics, frame_metrics, trajectory_metrics

FrameFn = Callable[[Any], "np.ndarray | None"]


@dataclass
class OdometryResult:
    """Outcome of :func:`run_odometry`.

    Attributes:
        method: estimator method name.
        seed: seed of the estimator's random stream.
        poses: ``(F+1, 4, 4)`` estimated camera-to-world poses, ``poses[0] = true_poses[0]``.
        true_poses: ``(F+1, 4, 4)`` true camera-to-world poses.
        frames: per-frame metrics of the estimator's own output (a failed frame
            is scored on what the estimator returned, not on the fallback).
        fallback: ``(F,)`` True where the estimate failed and the previous
            frame's motion was reused (constant velocity).
        trajectory: metrics of ``poses`` against ``true_poses``.
        frame_indices: ``(F,)`` the simulator's index of each frame.
        covariances: ``(F, 6, 6)`` each frame's motion covariance
            (:attr:`stereovo.estimation.MotionEstimate.covariance`: error vector
            ``(log(R_est R_true^T), t_est - t_true)``, rad then m); NaN where the estimate failed.
    """

    method: str
    seed: Any
    poses: np.ndarray
    true_poses: np.ndarray
    frames: list[FrameMetrics]
    fallback: np.ndarray
    trajectory: TrajectoryMetrics
    frame_indices: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    covariances: np.ndarray = field(default_factory=lambda: np.zeros((0, 6, 6)))

    @property
    def n_frames(self) -> int:
        return len(self.frames)

    @property
    def n_failed(self) -> int:
        """Frames whose estimate failed (and used the constant-velocity fallback)."""
        return int(np.count_nonzero(self.fallback))

    def column(self, name: str) -> np.ndarray:
        """One per-frame metric as an ``(F,)`` array, e.g. ``column("rot_err_deg")``."""
        return np.array([getattr(m, name) for m in self.frames])

    def rows(self) -> list[dict[str, Any]]:
        """One dict per frame (frame index, every FrameMetrics field, fallback) for CSV export."""
        return [
            {"frame": int(k), **m.as_dict(), "fallback": bool(fb)}
            for k, m, fb in zip(self.frame_indices, self.frames, self.fallback)
        ]

    def summary(self) -> dict[str, Any]:
        """Headline numbers: per-frame aggregates plus the trajectory metrics (units in the keys)."""

        def agg(fn: Callable[[np.ndarray], Any], name: str) -> float:
            values = self.column(name).astype(float)
            return float(fn(values)) if values.size else float("nan")

        return {
            "method": self.method,
            "frames": self.n_frames,
            "failed_frames": self.n_failed,
            "success_rate": agg(np.mean, "success"),
            "median_rot_err_deg": agg(np.median, "rot_err_deg"),
            "median_trans_err_m": agg(np.median, "trans_err_m"),
            "mean_precision": agg(np.mean, "precision"),
            "mean_recall": agg(np.mean, "recall"),
            "median_hypotheses": agg(np.median, "n_hypotheses"),
            "median_time_s": agg(np.median, "time_s"),
            **self.trajectory.as_dict(),
        }


def run_odometry(
    sequence: Any,
    method: str = "probabilistic",
    seed: int | np.random.Generator | None = 0,
    progress: bool = False,
    priors_fn: FrameFn | None = None,
    order_fn: FrameFn | None = None,
    kitti_lengths: Sequence[float] = KITTI_LENGTHS,
    kitti_step: int = KITTI_STEP,
    on_estimate: Callable[[Any, Any], None] | None = None,
    estimate_fn: Callable[[Any, np.random.Generator], Any] | None = None,
    **estimator_options: Any,
) -> OdometryResult:
    """Run frame-to-frame odometry over a ``stereovo.simulation.Sequence``.

    Args:
        sequence: iterable of ``Frame`` s with ``true_poses (F+1, 4, 4)``.
        method: an ``available_methods()`` name.
        seed: seeds one random stream shared by all frames, so a run is
            reproducible bit for bit; a ``Generator`` is used as is.
        progress: show a tqdm progress bar.
        priors_fn: ``frame -> (N,) priors or None`` for guided sampling, e.g.
            ``lambda f: f.scores``.
        order_fn: ``frame -> (N,) ordering or None`` for PROSAC-style methods.
        on_estimate: optional ``(frame, estimate) -> None`` called after each frame's estimate
            (e.g. a learned sampler that feeds the last motion into its next frame's features).
        estimate_fn: optional ``(frame, rng) -> MotionEstimate`` that replaces the core's
            ``estimate_motion`` call (e.g. a learned in-frame sampler that runs its own search);
            ``rng`` is the run's shared stream. With it, ``priors_fn``, ``order_fn`` and
            ``estimator_options`` are not used and must not be given.
        kitti_lengths, kitti_step: KITTI segment lengths (m) and start stride
            (frames) for the trajectory drift metric.
        **estimator_options: passed to every ``estimate_motion`` call. A
            ``noise_sigma`` here overrides the frames' own (the estimator needs
            a positive one even for noise-free simulations).
    """
    for key in ("priors", "order"):
        if estimator_options.get(key) is not None:
            raise ValueError(f"{key}= differs per frame: pass {key}_fn=callable(frame) instead")
        estimator_options.pop(key, None)
    noise_sigma = estimator_options.pop("noise_sigma", None)
    if estimate_fn is not None and (priors_fn is not None or order_fn is not None or estimator_options
                                    or noise_sigma is not None):
        raise ValueError("estimate_fn= runs its own estimator: priors_fn, order_fn and estimator options "
                         "are not used with it")
    rng = np.random.default_rng(seed)
    true_poses = np.asarray(sequence.true_poses, dtype=float)
    chain = PoseChain(true_poses[0])
    metrics: list[FrameMetrics] = []
    indices: list[int] = []
    covariances: list[np.ndarray] = []

    for frame in _progress(sequence, progress, method):
        if estimate_fn is not None:
            est = estimate_fn(frame, rng)
        else:
            est = estimate_motion(
                frame.prev,
                frame.curr,
                frame.camera,
                method=method,
                priors=priors_fn(frame) if priors_fn is not None else None,
                order=order_fn(frame) if order_fn is not None else None,
                rng=rng,
                noise_sigma=frame.noise_sigma if noise_sigma is None else noise_sigma,
                **estimator_options,
            )
        if on_estimate is not None:
            on_estimate(frame, est)
        # A failed frame keeps the last motion: constant-velocity fallback.
        chain.append(est.ok, est.rotation, est.translation)
        metrics.append(frame_metrics(est, frame.truth))
        covariances.append(est.covariance if est.covariance is not None else np.full((6, 6), np.nan))
        indices.append(int(frame.index))

    est_poses = np.stack(chain.poses)
    true_poses = true_poses[: len(est_poses)]
    return OdometryResult(
        method=method,
        seed=seed,
        poses=est_poses,
        true_poses=true_poses,
        frames=metrics,
        fallback=np.array(chain.fallbacks, dtype=bool),
        trajectory=trajectory_metrics(est_poses, true_poses, kitti_lengths=kitti_lengths, kitti_step=kitti_step),
        frame_indices=np.array(indices, dtype=int),
        covariances=np.array(covariances, dtype=float).reshape(-1, 6, 6),
    )


def _progress(frames: Iterable[Any], enabled: bool, desc: str) -> Iterable[Any]:
    if not enabled:
        return frames
    from tqdm.auto import tqdm

    total = len(frames) if hasattr(frames, "__len__") else None
    return tqdm(frames, total=total, desc=desc, unit="frame", dynamic_ncols=True)
