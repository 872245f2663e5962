"""The public entry point: :func:`estimate_motion`, :func:`estimate_problem` and their :class:`MotionEstimate`.

The entry point builds the frame's :class:`~stereovo.estimation.problem.StereoProblem`, looks the
method up in the registry (:mod:`stereovo.estimation.registry`), runs it on the usable rows and
scatters the result back to all rows. The methods themselves live in :mod:`stereovo.estimation.recipes`
(the core's own) and :mod:`stereovo.estimation.methods` (one module per paper).
"""

from __future__ import annotations

import dataclasses
import functools
import time
from dataclasses import dataclass

import numpy as np

from stereovo.camera import StereoCamera
from stereovo.estimation.covariance import pose_covariance
from stereovo.estimation.estimator_options import EstimatorOptions
from stereovo.estimation.loop import RansacReport
from stereovo.estimation.problem import StereoProblem
from stereovo.estimation.registry import MethodSpec, method_spec, refuse_unread, split_options
from stereovo.estimation.roles.samplers import validate_order, validate_priors
from stereovo.estimation.roles.solvers import SAMPLE_SIZE
from stereovo.seeding import generator_from_seed_words, seed_words

__all__ = ["MotionEstimate", "PreparedEstimator", "as_generator", "estimate_motion", "estimate_problem"]


@dataclass
class MotionEstimate:
    """The result of :func:`estimate_motion`.

    Attributes:
        rotation, translation: ``(3, 3)`` and ``(3,)``, ``x_k = R x_{k-1} + t`` (identity on failure).
        inliers: ``(N,)`` bool mask of the final model's inliers (False on unusable rows).
        status: ``"ok"`` or ``"failed: <reason>"``.
        n_hypotheses: minimal samples drawn; n_scored: hypotheses verified;
        n_point_checks: point-hypothesis residual evaluations.
        time_s: wall time of the estimate in seconds.
        method: the method's name.
        score: the final model's quality under the method's own measure.
        report: the loop's full report on the usable rows (None when the frame failed before the
            loop); its masks have one entry per usable row.
        unusable: ``(N,)`` bool, the rows without a resolvable depth (NaN or inf, disparity at or
            below ``camera.min_disparity`` or within ``min_disparity_sigmas`` noise standard
            deviations at k-1 or k, or no finite triangulation: :mod:`stereovo.estimation.problem`). They were never
            sampled and are never inliers; see :attr:`n_unusable`.
        covariance: ``(6, 6)`` covariance of the motion's error vector
            ``e = (log(R_est R_true^T), t_est - t_true)`` (rotation first, rad, in the world-side,
            left-multiplied form; then translation, m), propagated from the pixel noise of both
            frames through the least-squares fit on the final inliers, plus the returned motion's
            offset from that fit where it is not that fit (no final refinement, or one rolled
            back: :func:`stereovo.estimation.covariance.pose_covariance`); None on a failed estimate.
            Computed on first read and then kept (it costs a noticeable share of an estimate,
            docs/performance.md, and the environment never reads it).
        counters: the method's own counters (e.g. T(d,d) passes, SPRT tests, local optimisation
            runs), name -> number, as its components report them (``RansacReport.counters``);
            empty for a method that reports none.
    """

    rotation: np.ndarray
    translation: np.ndarray
    inliers: np.ndarray
    status: str
    n_hypotheses: int
    n_scored: int
    n_point_checks: int
    time_s: float
    method: str
    score: float = float("-inf")
    report: RansacReport | None = None
    unusable: np.ndarray | None = None
    covariance: np.ndarray | None = None
    counters: dict = dataclasses.field(default_factory=dict)
    # (problem, R, t, inliers, fitted) of a covariance not computed yet; the property computes and keeps it.
    _covariance_source: tuple | None = dataclasses.field(default=None, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.unusable is None:
            self.unusable = np.zeros(np.shape(self.inliers)[0], dtype=bool)

    def defer_covariance(self, problem, rotation: np.ndarray, translation: np.ndarray, inliers: np.ndarray,
                         fitted: bool = True) -> None:
        """Make :attr:`covariance` the :func:`pose_covariance` of this motion on ``problem``,
        computed when first read; ``fitted``: whether it is the least-squares fit of ``inliers``
        (else its offset from that fit is added)."""
        self._covariance_source = (problem, rotation, translation, inliers, fitted)

    @classmethod
    def from_report(cls, report: RansacReport, method: str, time_s: float) -> "MotionEstimate":
        """The public view of one run of the loop (or of a direct estimator)."""
        return cls(
            rotation=report.rotation, translation=report.translation, inliers=report.inliers, status=report.status,
            n_hypotheses=report.n_hypotheses, n_scored=report.n_scored, n_point_checks=report.n_point_checks,
            time_s=time_s, method=method, score=report.score, report=report,
            counters=dict(getattr(report, "counters", None) or {}),
        )

    def on_all_rows(self, sub: StereoProblem, rows: np.ndarray | None, n: int) -> "MotionEstimate":
        """This estimate, made on the usable sub-problem ``sub`` whose rows are ``rows (M,)`` of the
        ``n`` given (None: all of them, :meth:`StereoProblem.usable_subproblem`), as one over all
        ``n`` rows: inliers scattered back, the other rows flagged unusable, and the covariance of a
        successful fit deferred on ``sub``. Returns ``self``."""
        if self.ok:
            # never taken as the least-squares fit of its inliers: a method without the final
            # refinement, a refinement rolled back, and inliers re-selected after the last fit (the
            # papers' one refit) all leave it off that fit (pose_covariance adds the offset)
            self.defer_covariance(sub, self.rotation, self.translation, self.inliers, fitted=False)
        if rows is not None:
            inliers = np.zeros(n, dtype=bool)
            inliers[rows] = self.inliers
            self.inliers = inliers
            self.unusable = np.ones(n, dtype=bool)
            self.unusable[rows] = False
        return self

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    @property
    def n_inliers(self) -> int:
        return int(np.count_nonzero(self.inliers))

    @property
    def n_unusable(self) -> int:
        """Number of rows without depth (:attr:`unusable`)."""
        return int(np.count_nonzero(self.unusable))


def _read_covariance(estimate: MotionEstimate) -> np.ndarray | None:
    source = estimate.__dict__.get("_covariance_source")
    if source is not None:
        estimate.__dict__["_covariance"] = pose_covariance(*source)
        estimate.__dict__["_covariance_source"] = None
    return estimate.__dict__.get("_covariance")


def _write_covariance(estimate: MotionEstimate, value: np.ndarray | None) -> None:
    estimate.__dict__["_covariance"] = value
    estimate.__dict__["_covariance_source"] = None


def _estimate_state(estimate: MotionEstimate) -> dict:
    _read_covariance(estimate)  # a pickled estimate carries its covariance, not the problem
    return dict(estimate.__dict__)


# After the decorator, so that the dataclass keeps ``covariance`` as its constructor argument
# (its __init__ assigns through the setter) while reads go through the lazy getter.
MotionEstimate.covariance = property(_read_covariance, _write_covariance, doc="See the class docstring.")
MotionEstimate.__getstate__ = _estimate_state


def as_generator(rng: np.random.Generator | int | np.random.SeedSequence | None, name: str = "rng") -> np.random.Generator:
    """The one way seeds become generators: an existing Generator is used as is; a seed (an integer
    >= 0, not a bool), a ``SeedSequence`` or None (fresh entropy) makes a new one. Anything else is a
    ValueError naming ``name`` and the value (numpy's own TypeError names neither)."""
    if isinstance(rng, np.random.Generator):
        return rng
    seed = isinstance(rng, (int, np.integer)) and not isinstance(rng, (bool, np.bool_)) and rng >= 0
    if not (rng is None or seed or isinstance(rng, np.random.SeedSequence)):
        raise ValueError(f"{name} must be a numpy.random.Generator, a SeedSequence or an integer seed >= 0, "
                         f"got {rng!r}")
    if rng is None:
        return np.random.default_rng()
    # default_rng's generator (its bit generator seeded alike), without its argument dispatch (~5 us)
    return np.random.Generator(np.random.PCG64(rng))


@functools.lru_cache(maxsize=1024)
def _seed_words(seed: int) -> np.ndarray:
    return seed_words(seed, [()])[0]


def _estimate_generator(rng: np.random.Generator | int | np.random.SeedSequence | None) -> np.random.Generator:
    """:func:`as_generator` of ``rng`` for an estimate's own draws. An integer seed (the common case:
    the benchmarks and environments seed every estimate) gets its PCG64 from cached seed words,
    bit for bit the state numpy's hashing gives (:mod:`stereovo.seeding`), in about a microsecond
    where numpy takes eight; that generator has no SeedSequence to spawn from, which no method asks."""
    if type(rng) is int and 0 <= rng < 2**63:
        return generator_from_seed_words(_seed_words(rng))
    return as_generator(rng)


def estimate_motion(
    prev: np.ndarray,
    curr: np.ndarray,
    camera: StereoCamera,
    method: str = "probabilistic",
    priors: np.ndarray | None = None,
    order: np.ndarray | None = None,
    rng: np.random.Generator | int | None = 0,
    **options,
) -> MotionEstimate:
    """Estimate the motion ``x_k = R x_{k-1} + t`` between two stereo frames.

    Args:
        prev, curr: ``(N, 4)`` stereo measurements ``(uL, vL, uR, vR)`` in pixels at k-1 and k;
            row i of both is one putative match.
        camera: the rectified stereo rig.
        method: a name from :func:`available_methods`.
        priors: optional ``(N,)`` non-negative sampling weights (guided sampling).
        order: optional ``(N,)`` permutation, best match first (PROSAC sampling).
        rng: a ``numpy.random.Generator`` or a seed; the same seed gives the same result.
        **options: fields of :class:`stereovo.estimation.EstimatorOptions` (the options every method
            shares) and the method's own (``method_spec(method).extra_options``). Match scores reach a
            method only through ``priors=`` or ``order=``. An option the method would not read with
            the others is refused (:func:`~stereovo.estimation.registry.unread_options`: e.g.
            ``confidence`` under a fixed ``budget``, ``least_squares_refit`` with ``refine=True``,
            ``gate_probability`` for a method judged by the reprojection gate).

    Returns:
        A :class:`MotionEstimate`. Rows without a resolvable depth (NaN or inf; disparity at or
        below ``camera.min_disparity``, or at or below ``min_disparity_sigmas`` standard deviations
        of its noise, at k-1 or k) are outliers: the method runs on the other rows and the
        estimate names them (``unusable``, ``n_unusable``). A hopeless frame (fewer than 3 or
        ``min_inliers`` usable rows, every sample degenerate, no consensus, or an adaptive search
        that reached ``max_iterations`` before its stop with ``fail_at_cap``) gives
        ``status="failed: ..."`` with identity motion; it never raises. ``"ok"`` means the
        returned pose is finite and the returned inliers are exactly the rows that pass the
        method's own final gate under it, at least ``min_inliers`` of them
        (:func:`stereovo.estimation.loop.final_report`).

    Raises:
        ValueError: malformed input (shapes, mismatched N, complex or non-numeric values), bad
            priors/order, an unknown method or option, a bad value (naming it), or an option the
            method would not read (``"method 'ransac': confidence=0.5 would be ignored: a fixed budget
            (budget=64) draws ..."``, naming each such option, its value and why).
    """
    start = time.perf_counter()
    spec = method_spec(method)
    shared, extra = split_options(spec, options)
    refuse_unread(spec, shared, options, order is not None, extra)
    problem = StereoProblem.build(prev, curr, camera, shared.noise_sigma, shared.min_disparity_sigmas)
    return _estimate(problem, spec, shared, extra, priors, order, rng, start)


def problem_options(spec: MethodSpec, problem: StereoProblem, options: dict,
                    order: bool | None = None) -> tuple[EstimatorOptions, dict]:
    """The shared and the method's own options of an estimate on a built ``problem``: its pixel noise
    and disparity rule fill in, and a caller's differing value is refused (the covariances and the
    unusable rows were computed with the problem's), as is an option the method would not read
    (``order``: whether it gets ``order=``, :func:`~stereovo.estimation.registry.unread_options`)."""
    if "noise_sigma" in options and options["noise_sigma"] != problem.noise_sigma:
        raise ValueError(
            f"noise_sigma={options['noise_sigma']!r} differs from the problem's {problem.noise_sigma!r}, "
            "with which its covariances were computed"
        )
    if "min_disparity_sigmas" in options and options["min_disparity_sigmas"] != problem.min_disparity_sigmas:
        raise ValueError(
            f"min_disparity_sigmas={options['min_disparity_sigmas']!r} differs from the problem's "
            f"{problem.min_disparity_sigmas!r}, with which its unusable rows were chosen"
        )
    shared, extra = split_options(
        spec, {**options, "noise_sigma": problem.noise_sigma, "min_disparity_sigmas": problem.min_disparity_sigmas}
    )
    refuse_unread(spec, shared, options, order, extra)
    return shared, extra


def estimate_problem(
    problem: StereoProblem, method: str = "probabilistic", priors: np.ndarray | None = None,
    order: np.ndarray | None = None, rng: np.random.Generator | int | None = 0, **options,
) -> MotionEstimate:
    """:func:`estimate_motion` on an already built :class:`StereoProblem`.

    For callers that use the same frame's triangulated points elsewhere (the environment
    computes its observation features from them): the problem is built, validated and
    triangulated once. The result is identical to ``estimate_motion(problem.prev,
    problem.curr, problem.camera, ..., noise_sigma=problem.noise_sigma)``.

    Raises:
        ValueError: as :func:`estimate_motion` (an option the method would not read included), and
            if a ``noise_sigma`` option differs from the one the problem was built with.
    """
    start = time.perf_counter()
    if not isinstance(problem, StereoProblem):
        raise ValueError(f"problem must be a StereoProblem, got {type(problem).__name__}")
    spec = method_spec(method)
    shared, extra = problem_options(spec, problem, options, order is not None)
    return _estimate(problem, spec, shared, extra, priors, order, rng, start)


class PreparedEstimator:
    """One method with one set of options, for many frames: :meth:`estimate` is :func:`estimate_problem`.

    ``PreparedEstimator(method, **options).estimate(problem, priors, order, rng)`` returns what
    ``estimate_problem(problem, method, priors, order, rng, **options)`` returns, bit for bit, and
    raises what it raises. It looks the method up once, and derives and checks the options (the
    shared :class:`EstimatorOptions` and the method's own) once per pixel noise and disparity rule of
    the problems it gets, instead of on every call (about a sixth of an estimate at a budget of 32
    hypotheses: the environment's case, one estimate a step).

    Args:
        method: a name from :func:`~stereovo.estimation.available_methods` (ValueError if unknown).
        **options: as :func:`estimate_problem`'s; checked on the first estimate, as there.
    """

    _MAX_PREPARED = 16  # derived option sets kept (one per noise, disparity rule and order= or not; an env has one)

    def __init__(self, method: str = "probabilistic", **options) -> None:
        self._spec = method_spec(method)
        self._options = dict(options)
        self._prepared: dict[tuple, tuple[EstimatorOptions, dict]] = {}

    @property
    def method(self) -> str:
        """The method's name."""
        return self._spec.name

    @property
    def options(self) -> dict:
        """The options as given (a copy)."""
        return dict(self._options)

    def _derived(self, problem: StereoProblem, order: bool) -> tuple[EstimatorOptions, dict]:
        """The options of an estimate on ``problem`` with or without ``order=``, as
        :func:`estimate_problem` derives and checks them (whether an option is read can depend on the order)."""
        key = (problem.noise_sigma, problem.min_disparity_sigmas, order)
        derived = self._prepared.get(key)
        if derived is None:
            derived = problem_options(self._spec, problem, self._options, order)
            if len(self._prepared) >= self._MAX_PREPARED:
                self._prepared.clear()
            self._prepared[key] = derived
        return derived

    def estimate(
        self, problem: StereoProblem, priors: np.ndarray | None = None, order: np.ndarray | None = None,
        rng: np.random.Generator | int | None = 0,
    ) -> MotionEstimate:
        """:func:`estimate_problem` of ``problem`` with this method and these options."""
        start = time.perf_counter()
        if not isinstance(problem, StereoProblem):
            raise ValueError(f"problem must be a StereoProblem, got {type(problem).__name__}")
        shared, extra = self._derived(problem, order is not None)
        # a copy of the method's options per call, as estimate_problem hands each call its own
        return _estimate(problem, self._spec, shared, dict(extra), priors, order, rng, start)

    def __getstate__(self) -> dict:
        # by name: the registry's method specs hold local functions, which do not pickle
        return {"method": self.method, "options": self._options}

    def __setstate__(self, state: dict) -> None:
        self.__init__(state["method"], **state["options"])

    def __repr__(self) -> str:
        return f"PreparedEstimator({self.method!r}, {len(self._options)} options)"


def _estimate(
    problem: StereoProblem,
    spec: MethodSpec,
    shared: EstimatorOptions,
    extra: dict,
    priors: np.ndarray | None,
    order: np.ndarray | None,
    rng: np.random.Generator | int | None,
    start: float,
) -> MotionEstimate:
    """Validate priors/order, run the method on ``problem``'s usable rows and scatter the result
    back to all N rows; ``start`` is the caller's perf_counter."""
    method = spec.name
    spec.check_inputs(priors is not None, order is not None)
    for name, value in (("priors", priors), ("order", order)):
        if value is not None and np.shape(value) != (problem.n,):
            raise ValueError(f"{name} must have shape ({problem.n},), one entry per correspondence, got {np.shape(value)}")
    generator = _estimate_generator(rng)
    unusable = ~problem.usable_mask
    need = max(SAMPLE_SIZE, shared.min_inliers)

    def failed(reason: str) -> MotionEstimate:
        return MotionEstimate(
            np.eye(3), np.zeros(3), np.zeros(problem.n, dtype=bool), f"failed: {reason}",
            0, 0, 0, time.perf_counter() - start, method, unusable=unusable,
        )

    if problem.n < need:
        return failed(f"too few correspondences ({problem.n}, need {need})")
    if priors is not None:
        priors = np.ascontiguousarray(validate_priors(priors, problem.n))  # one layout for the compiled draws
    if order is not None:
        order = validate_order(order, problem.n)
    sub, rows = problem.usable_subproblem()
    if rows is not None:
        if rows.size < need:
            return failed(f"too few usable correspondences ({rows.size} of {problem.n} usable, need {need})")
        if priors is not None:
            priors = priors[rows]
            if np.count_nonzero(priors > 0) < SAMPLE_SIZE:
                return failed(
                    f"priors have fewer than {SAMPLE_SIZE} positive weights on the {rows.size} usable correspondences"
                )
        if order is not None:
            # the permutation's relative order of the usable rows, renumbered within the sub-problem
            position = np.cumsum(problem.usable) - 1
            order = position[order[problem.usable[order]]]
    report = spec.run(sub, shared, priors, order, extra, generator)
    estimate = MotionEstimate.from_report(report, method, 0.0).on_all_rows(sub, rows, problem.n)
    estimate.time_s = time.perf_counter() - start
    return estimate
