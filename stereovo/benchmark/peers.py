"""Our estimator and other robust-estimation libraries as interchangeable runners on one frame.

A runner is ``run(frame, seed) -> Outcome``: the motion it estimates between the frame's k-1 and
k and the wall time of the estimate alone. Our runner's time includes building the problem
(validation, triangulation of both frames with covariances); a peer is handed the left-image
pixels at k and the 3-D points triangulated at k-1 (PnP) or at both frames (3-D-3-D) before its
clock starts. Every peer is optional: its factory returns None when its package is missing.

The peers:

- OpenCV's ``solvePnPRansac`` (AP3P with OpenCV's RANSAC) and its USAC framework
  (``flags=cv2.USAC_DEFAULT``; Ivashechkin, Barath & Matas, "USACv20: robust essential, fundamental
  and homography matrix estimation", arXiv 2104.05044);
- PoseLib's ``estimate_absolute_pose`` (Larsson & contributors, PoseLib, 2020);
- SupeRANSAC (Barath, "SupeRANSAC: One RANSAC to Rule Them All", arXiv 2506.04803, 2025; the
  ``pysuperansac`` wheel): ``estimateAbsolutePose`` (PnP) and ``estimateRigidTransform`` (3-D-3-D),
  with its uniform, PROSAC, importance or AR sampler; the last two take per-point probabilities,
  which we feed the same calibrated match scores our guided sampling gets. Its quirks
  (docs/performance.md): it takes no seed (every call draws anew), it overwrites the settings'
  ``inlier_threshold`` with the threshold in normalised coordinates (so a settings object must not
  be reused), ``min_iterations`` defaults to 1000, and the rigid transform comes back as a 4x4 for
  row vectors (``y = x R' + t'`` with the translation in the last row).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

PEER_REPROJECTION_PX = 2.0  # peers judge one image; 2 px at sigma 0.5 is their usual setting
PEER_MAX_ITERATIONS = 10_000
PEER_CONFIDENCE = 0.99
RIGID_THRESHOLD_M = 0.3  # SupeRANSAC's 3-D-3-D inlier distance (m): see docs/performance.md for the sweep
SAMPLINGS = ("uniform", "prosac", "guided")  # what our runner samples by: nothing, the scores' order, the scores as priors
SUPERANSAC_SAMPLERS = ("uniform", "prosac", "importance", "ar")


@dataclass
class Outcome:
    """One estimate: ``rotation (3, 3)`` and ``translation (3,)`` of ``x_k = R x_{k-1} + t``, the
    hypotheses drawn (-1 where the library does not say) and the estimate's wall time (s)."""

    rotation: np.ndarray
    translation: np.ndarray
    hypotheses: int
    seconds: float


Runner = Callable[..., Outcome]
FAILED = (np.eye(3), np.zeros(3))
CLOCKS = {"wall": time.perf_counter, "cpu": time.process_time}
clock = time.perf_counter  # what every runner times with: set_clock("cpu") on a shared machine


def set_clock(name: str) -> None:
    """Time the runners by wall clock ("wall", the default) or by this process' CPU time ("cpu":
    every library here runs single-threaded, so that is its wall time minus the time other jobs
    held the core)."""
    global clock
    if name not in CLOCKS:
        raise ValueError(f"clock must be one of {sorted(CLOCKS)}, got {name!r}")
    clock = CLOCKS[name]


def with_depth(frame, both: bool = False) -> np.ndarray:
    """``(M,)`` the rows a peer can be handed: finite, with a disparity above ``camera.min_disparity``
    at k-1 (and at k with ``both``), in their order. A PnP user drops the others before calling a
    library (it cannot triangulate them); the hostile preset's far clutter and independent
    mismatches make such rows."""
    cam = frame.camera
    ok = np.all(np.isfinite(frame.prev), axis=1) & (cam.disparity(frame.prev) > cam.min_disparity)
    if both:
        ok &= np.all(np.isfinite(frame.curr), axis=1) & (cam.disparity(frame.curr) > cam.min_disparity)
    return np.flatnonzero(ok)


def score_order(frame) -> np.ndarray:
    """``(N,)`` the matches by descending score (what PROSAC samples by), ties in index order."""
    return np.argsort(-frame.scores, kind="stable")


def ours(method: str = "probabilistic", sampling: str = "uniform", **options) -> Runner:
    """Our ``estimate_motion(method=...)``; ``sampling`` "prosac" passes the scores' order, "guided"
    the calibrated scores as priors (``Frame.match_probabilities``); ``options`` go to the estimator
    (``confidence``, ``max_iterations``, ``budget``, ...)."""
    from stereovo import estimate_motion

    if sampling not in SAMPLINGS:
        raise ValueError(f"sampling must be one of {SAMPLINGS}, got {sampling!r}")

    def run(frame, seed: int) -> Outcome:
        given = {}
        if sampling == "prosac":
            given["order"] = score_order(frame)
        elif sampling == "guided":
            given["priors"] = frame.match_probabilities
        start = clock()
        est = estimate_motion(frame.prev, frame.curr, frame.camera, method=method, rng=seed,
                              noise_sigma=frame.noise_sigma, **given, **options)
        elapsed = clock() - start
        return Outcome(est.rotation, est.translation, est.n_hypotheses, elapsed)

    return run


def opencv(usac: bool = False, max_iterations: int = PEER_MAX_ITERATIONS, confidence: float = PEER_CONFIDENCE,
           threshold_px: float = PEER_REPROJECTION_PX) -> Runner | None:
    """OpenCV's ``solvePnPRansac``: AP3P in its RANSAC, or its USAC framework; one thread."""
    try:
        import cv2
    except ImportError:
        return None
    cv2.setNumThreads(1)
    flags = cv2.USAC_DEFAULT if usac else cv2.SOLVEPNP_AP3P

    def run(frame, seed: int) -> Outcome:
        cv2.setRNGSeed(seed)
        rows = with_depth(frame)
        X = frame.camera.triangulate(frame.prev[rows])
        pixels = frame.curr[rows, :2].copy()
        start = clock()
        ok, rvec, tvec, _ = cv2.solvePnPRansac(
            X, pixels, frame.camera.intrinsics, None, iterationsCount=int(max_iterations),
            reprojectionError=threshold_px, confidence=confidence, flags=flags,
        )
        elapsed = clock() - start
        if not ok:
            return Outcome(*FAILED, 0, elapsed)
        R, _ = cv2.Rodrigues(rvec)
        return Outcome(R, tvec.ravel(), -1, elapsed)  # OpenCV does not report its iterations

    return run


def poselib(max_iterations: int = PEER_MAX_ITERATIONS, confidence: float = PEER_CONFIDENCE,
            threshold_px: float = PEER_REPROJECTION_PX, min_iterations: int | None = None) -> Runner | None:
    """PoseLib's ``estimate_absolute_pose`` (P3P, LO-RANSAC, its own refinement); ``min_iterations``
    None keeps PoseLib's own floor (1000 iterations in PoseLib 2.0)."""
    try:
        import poselib as lib
    except ImportError:
        return None

    def run(frame, seed: int) -> Outcome:
        cam = frame.camera
        camera = {"model": "PINHOLE", "width": cam.width, "height": cam.height, "params": [cam.fx, cam.fy, cam.cx, cam.cy]}
        rows = with_depth(frame)
        X = cam.triangulate(frame.prev[rows])
        pixels = frame.curr[rows, :2].copy()
        options = {"max_reproj_error": threshold_px, "max_iterations": int(max_iterations), "success_prob": confidence,
                   "seed": seed}
        if min_iterations is not None:
            options["min_iterations"] = int(min(min_iterations, max_iterations))
        start = clock()
        pose, info = lib.estimate_absolute_pose(pixels, X, camera, options, {})
        elapsed = clock() - start
        return Outcome(pose.R, np.asarray(pose.t), int(info.get("iterations", -1)), elapsed)

    return run


def superansac_available() -> bool:
    try:
        import pysuperansac  # noqa: F401
    except ImportError:
        return False
    return True


def superansac(sampler: str = "uniform", rigid: bool = False, max_iterations: int = PEER_MAX_ITERATIONS,
               confidence: float = PEER_CONFIDENCE, min_iterations: int = 1, threshold: float | None = None
               ) -> Runner | None:
    """SupeRANSAC's PnP (``rigid=False``, ``threshold`` in pixels, default 2) or 3-D-3-D rigid
    transform (``threshold`` in metres, default :data:`RIGID_THRESHOLD_M`), with its MAGSAC scoring,
    nested-RANSAC local optimisation and iterated least-squares polish (its defaults).

    ``sampler``: "uniform"; "prosac" (the matches handed over by descending score); "importance" or
    "ar" (its importance and adaptive-reordering samplers, fed ``Frame.match_probabilities``).
    ``min_iterations`` is 1 here, not its default 1000, so that its stop, like ours, is the bound
    alone. It takes no seed: ``seed`` is ignored and repeated runs differ.
    """
    if sampler not in SUPERANSAC_SAMPLERS:
        raise ValueError(f"sampler must be one of {SUPERANSAC_SAMPLERS}, got {sampler!r}")
    if not superansac_available():
        return None
    import pysuperansac as sr

    kinds = {"uniform": sr.SamplerType.Uniform, "prosac": sr.SamplerType.PROSAC,
             "importance": sr.SamplerType.ImportanceSampler, "ar": sr.SamplerType.ARSampler}
    limit = float(threshold if threshold is not None else (RIGID_THRESHOLD_M if rigid else PEER_REPROJECTION_PX))

    def settings():
        # a fresh object per call: the library overwrites inlier_threshold with its normalised value
        s = sr.RANSACSettings()
        s.inlier_threshold = limit
        s.max_iterations = int(max_iterations)
        s.min_iterations = int(min(min_iterations, max_iterations))
        s.confidence = float(confidence)
        s.sampler = kinds[sampler]
        return s

    def run(frame, seed: int) -> Outcome:
        cam = frame.camera
        if not rigid and cam.fx != cam.fy:
            raise ValueError(f"superansac: its PnP takes one focal length, got fx {cam.fx} and fy {cam.fy}")
        usable = with_depth(frame, both=rigid)
        rows = usable[np.argsort(-frame.scores[usable], kind="stable")] if sampler == "prosac" else usable
        X = cam.triangulate(frame.prev[rows])
        probabilities = list(frame.match_probabilities[rows]) if sampler in ("importance", "ar") else []
        config = settings()
        if rigid:
            Y = cam.triangulate(frame.curr[rows])
            corr = np.ascontiguousarray(np.hstack([X, Y]))
            extent = list(np.ptp(corr, axis=0))
            start = clock()
            T, _, _, iterations = sr.estimateRigidTransform(corr, extent, probabilities, config)
            elapsed = clock() - start
            T = np.asarray(T)
            # row vectors: y = x T[:3, :3] + T[3, :3], i.e. R = T[:3, :3]^T, t = T[3, :3]
            R, t = T[:3, :3].T.copy(), T[3, :3].copy()
        else:
            corr = np.ascontiguousarray(np.hstack([frame.curr[rows, :2], X]))
            start = clock()
            R, t, _, _, iterations = sr.estimateAbsolutePose(
                corr, sr.CameraType.SimplePinhole, [cam.fx, cam.cx, cam.cy], [cam.width, cam.height], probabilities,
                config,
            )
            elapsed = clock() - start
            R, t = np.asarray(R), np.asarray(t).ravel()
        if not (np.all(np.isfinite(R)) and np.all(np.isfinite(t))):
            return Outcome(*FAILED, int(iterations), elapsed)
        return Outcome(R, t, int(iterations), elapsed)

    return run


def frame_errors(outcome: Outcome, frame) -> tuple[float, float, bool]:
    """``(rotation error in degrees, translation error in metres, success)`` of ``outcome`` against
    the frame's truth (success as :func:`stereovo.metrics.is_success`)."""
    from stereovo.geometry import rotation_error
    from stereovo.metrics import is_success

    r_err = float(rotation_error(outcome.rotation, frame.truth.rotation))
    t_err = float(np.linalg.norm(outcome.translation - frame.truth.translation))
    return float(np.degrees(r_err)), t_err, bool(is_success(r_err, t_err, np.linalg.norm(frame.truth.translation)))
