"""Sequences named by a source string, and visual odometry over any frame sequence.

:func:`open_source` turns ``"rendered"`` (or ``"rendered:car"``, ``"rendered:free"``) and
``"kitti:PATH[:SEQ]"`` into a sequence; :func:`run_image_odometry` runs frame-to-frame odometry
over it and, when the poses are known, scores it (per-frame success, KITTI drift) exactly as
:func:`stereovo.odometry.run_odometry` scores the simulator's sequences.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from stereovo.estimation import estimate_motion
from stereovo.geometry import PoseChain
from stereovo.odometry import OdometryResult, run_odometry

SOURCE_FORMS = ("rendered", "rendered:PRESET", "kitti:PATH", "kitti:PATH:SEQ")
"""The forms of a source string."""


def parse_source(text: str) -> tuple[str, dict[str, Any]]:
    """``("rendered", {"preset": ...})`` or ``("kitti", {"root": PATH, "sequence": SEQ})`` of a source string.

    ``kitti:PATH:SEQ`` with SEQ digits names sequence SEQ of PATH, unless ``PATH:SEQ`` is itself an
    existing folder: then it is ``kitti:PATH`` with that folder.

    Raises:
        ValueError: naming the string and the accepted forms.
    """
    if not isinstance(text, str) or not text:
        raise ValueError(f"source must be one of {', '.join(SOURCE_FORMS)}, got {text!r}")
    kind, _, rest = text.partition(":")
    if kind == "rendered":
        return "rendered", ({"preset": rest} if rest else {})
    if kind == "kitti" and rest:
        head, _, tail = rest.rpartition(":")
        # a folder whose own name ends in ':DIGITS' (e.g. 'run:2024') is that folder, not a sequence of another
        if head and tail.isdigit() and not Path(rest).expanduser().is_dir():
            return "kitti", {"root": head, "sequence": tail}
        return "kitti", {"root": rest, "sequence": None}
    raise ValueError(f"source must be one of {', '.join(SOURCE_FORMS)}, got {text!r}")


def open_source(text: str, **options: Any) -> Any:
    """The sequence a source string names.

    ``kitti:PATH`` without ``:SEQ`` takes PATH as one sequence's folder, or sequence ``00`` of a
    dataset folder. ``options`` go to :class:`~stereovo.sequences.rendered.RenderedSequence`
    (``n_frames``, ``seed``, ``resolution``, ``moving_objects``, front-end options, ...) or
    :class:`~stereovo.sequences.kitti.KittiOdometry` (``start``, ``stop``, front-end options).
    """
    kind, named = parse_source(text)
    if kind == "rendered":
        from stereovo.sequences.rendered import RenderedSequence

        return RenderedSequence(**{**named, **options})
    from stereovo.sequences.kitti import KittiOdometry

    root, sequence = named["root"], named["sequence"]
    if sequence is None and not (Path(root).expanduser() / "image_0").is_dir():
        sequence = "00"
    return KittiOdometry(root, sequence, **options)


@dataclass
class TrajectoryEstimate:
    """Odometry over a sequence without known poses: the estimated trajectory only.

    Attributes:
        poses: ``(F+1, 4, 4)`` estimated camera-to-world poses (the first the identity).
        ok: ``(F,)`` whether each frame's estimate succeeded (else constant velocity was used).
        n_matches, n_inliers: ``(F,)`` putative matches and inliers of each frame.
    """

    method: str
    poses: np.ndarray
    ok: np.ndarray
    n_matches: np.ndarray
    n_inliers: np.ndarray


def run_image_odometry(sequence: Any, method: str = "probabilistic", seed: int | np.random.Generator | None = 0,
                       progress: bool = False, use_scores: bool = False,
                       priors_fn: Callable[[Any], Any] | None = None, order_fn: Callable[[Any], Any] | None = None,
                       on_estimate: Callable[[Any, Any], None] | None = None,
                       estimate_fn: Callable[[Any, np.random.Generator], Any] | None = None,
                       **estimator_options: Any) -> OdometryResult | TrajectoryEstimate:
    """Frame-to-frame odometry over a frame sequence (rendered, KITTI, or the simulator's).

    Args:
        sequence: a frame sequence (:mod:`stereovo.sequences.base`).
        method: an estimator method name (:func:`stereovo.estimation.available_methods`).
        seed: the estimator's random stream.
        progress: a tqdm progress bar.
        use_scores: pass each frame's match scores as the sampler's priors (guided methods).
        priors_fn, order_fn, on_estimate, estimate_fn: per-frame hooks, as
            :func:`stereovo.odometry.run_odometry`'s (``priors_fn`` replaces ``use_scores``).
        **estimator_options: passed to every :func:`~stereovo.estimation.estimate_motion` call.

    Returns:
        an :class:`~stereovo.odometry.OdometryResult` (per-frame metrics, drift) when the poses
        are known, else a :class:`TrajectoryEstimate`.
    """
    if use_scores and priors_fn is None:
        priors_fn = lambda frame: frame.scores  # noqa: E731
    if getattr(sequence, "true_poses", None) is not None:
        return run_odometry(sequence, method=method, seed=seed, progress=progress, priors_fn=priors_fn,
                            order_fn=order_fn, on_estimate=on_estimate, estimate_fn=estimate_fn,
                            **estimator_options)
    if estimate_fn is not None and (priors_fn is not None or order_fn is not None or estimator_options):
        raise ValueError("estimate_fn= runs its own estimator: priors, order and estimator options "
                         "are not used with it")
    rng = np.random.default_rng(seed)
    chain = PoseChain(np.eye(4))
    ok, n_matches, n_inliers = [], [], []
    frames = iter(sequence)
    if progress:
        from tqdm.auto import tqdm

        frames = tqdm(frames, total=len(sequence), desc=method, unit="frame", dynamic_ncols=True)
    for frame in frames:
        if estimate_fn is not None:
            est = estimate_fn(frame, rng)
        else:
            est = estimate_motion(frame.prev, frame.curr, frame.camera, method=method, rng=rng,
                                  priors=priors_fn(frame) if priors_fn else None,
                                  order=order_fn(frame) if order_fn else None,
                                  **{"noise_sigma": frame.noise_sigma, **estimator_options})
        if on_estimate is not None:
            on_estimate(frame, est)
        chain.append(est.ok, est.rotation, est.translation)
        ok.append(bool(est.ok))
        n_matches.append(frame.n)
        n_inliers.append(int(est.n_inliers))
    return TrajectoryEstimate(method, np.stack(chain.poses), np.array(ok, bool), np.array(n_matches), np.array(n_inliers))
