"""``LearnedEstimator``: a learned RANSAC sampler on anyone's stereo matches.

The environments build a sampler's inputs from their own simulated frames; this is the same
recipe on user-supplied arrays, for both kinds of sampler:

- **one-shot** (``ngransac-*``, ``ppo``, or a file of :func:`agents.checkpoint.save_checkpoint`):
  the frame features (:func:`vo_gym.features.compute_features`, with the previous frame's
  estimated motion for the constant-velocity columns) go through the network once; its weights
  are the guided-sampling priors of the shared core (:func:`stereovo.estimation.estimate_problem`),
  which draws a fixed ``budget`` of hypotheses or stops adaptively with the prior-aware bound (the
  all-inlier chance of one draw *from these priors*, :mod:`stereovo.estimation.roles.termination`);
- **in-frame** (``adaptive-pg-prior``, ``adaptive-pg``, or a file of
  :func:`agents.adaptive.checkpoint.save_adaptive`): the sampler steers the search batch by batch
  (:class:`vo_gym.in_frame.InFrameSearch`, the adaptive environment's loop), reading the loop's
  evidence after each batch, and ends the frame with its own stop and its own selection of the
  hypothesis to refine.

Both networks are permutation-equivariant, so any number of matches works. The estimator keeps the
motion of the last successful estimate between calls (a sequence's constant-velocity prediction,
as in the environments); :meth:`LearnedEstimator.reset` forgets it at a new sequence.

Per-frame cost (N 500, one CPU thread, after the first call; ``scripts/bench_learned_estimator.py``
measures it): see ``docs/results.md``.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from agents.checkpoint import IN_FRAME, ONE_SHOT, CheckpointError
from agents.matches import UNINFORMATIVE_SCORE, match_features
from agents.samplers import load_sampler
from stereovo.camera import StereoCamera
from stereovo.estimation import StereoProblem, drop_unread, estimate_problem, method_spec, validate_options
from stereovo.estimation.api import MotionEstimate, as_generator
from stereovo.estimation.roles.solvers import SAMPLE_SIZE
from vo_gym.settings import DEFAULT_ESTIMATOR_OPTIONS
from vo_gym.in_frame import InFrameSearch

__all__ = ["LearnedEstimator", "LearnedMotionEstimate", "UNINFORMATIVE_SCORE", "DEFAULT_CONFIDENCE"]

DEFAULT_CONFIDENCE = {ONE_SHOT: 0.99, IN_FRAME: 0.9}
"""``confidence`` when not given: the prior-aware stop's (one-shot) or the stop belief's (in-frame)."""

IN_FRAME_BATCH = 4  # the adaptive environment's batch, which the in-frame samplers were trained with
IN_FRAME_CAP = 64  # its per-frame cap, which the 'spent' global is relative to


@dataclass
class LearnedMotionEstimate(MotionEstimate):
    """A :class:`stereovo.estimation.MotionEstimate` (same fields, same post-conditions) plus the
    learned sampler's ``sampler`` name and ``sampler_kind`` (``"one-shot"`` / ``"in-frame"``)."""

    sampler: str = ""
    sampler_kind: str = ""

    @classmethod
    def of(cls, estimate: MotionEstimate, sampler: str, kind: str) -> "LearnedMotionEstimate":
        out = cls.__new__(cls)
        out.__dict__.update(estimate.__dict__)  # keeps a covariance not computed yet lazy
        out.sampler, out.sampler_kind = sampler, kind
        return out


def _is_seed(value: Any) -> bool:
    return isinstance(value, (int, np.integer)) and not isinstance(value, bool) and value >= 0


def _bad_sampler(sampler: Any, err: Exception) -> ValueError:
    text = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
    return ValueError(f"sampler {os.fspath(sampler)!r}: {text}" if str(os.fspath(sampler)) not in text else text)


class LearnedEstimator:
    """Motion estimates from a learned sampler, frame after frame (see the module doc).

    Args:
        sampler: a shipped name (:data:`agents.checkpoint.SHIPPED_SAMPLERS`,
            :data:`agents.checkpoint.SHIPPED_IN_FRAME_SAMPLERS`), a checkpoint path of either kind,
            or a policy :func:`agents.checkpoint.load_sampler` returned (to share one loaded network).
        budget: hypotheses per frame. One-shot: exactly this many (None: the prior-aware adaptive
            stop at ``confidence``, capped by ``max_iterations``). In-frame: exactly this many batch
            after batch, the sampler's stop unused (None: its own stop, under the search's cap).
            For both kinds a budget is the stop itself: drawn in full, above ``max_iterations`` too
            (a one-shot budget is the core's, which refuses the options of the adaptive stop it
            replaces: ``max_iterations``, ``first_batch_size``, ``fail_at_cap``).
        confidence: in (0, 1); the prior-aware stop's confidence (one-shot, default 0.99) or the
            stop belief at which an in-frame sampler stops (default 0.9); refused with a ``budget``,
            under which no stop runs.
        method: the core method that fits and judges hypotheses (default ``"msac"``, the
            environments' judge, with which every shipped sampler was trained). An in-frame sampler
            draws from its own weights, so a method that needs ``priors=`` or ``order=`` from its
            caller (``guided-mlesac``, ``prosac``) is refused for it.
        max_hypotheses: an in-frame search's cap (None: 64, its training cap), which the sampler
            reads (hypotheses spent / cap); a ``max_iterations`` below it lowers the cap to it, and a
            ``budget`` above it raises the cap to the budget. Not for one-shot samplers (their
            adaptive stop is capped by ``max_iterations``).
        batch_size: hypotheses per batch of an in-frame search (default 4, its training batch).
        temperature: one-shot logits are divided by it (1: as trained); applied when the sampler is
            loaded here, so neither an in-frame sampler nor an already loaded policy takes another.
        **estimator_options: :class:`stereovo.estimation.EstimatorOptions` fields and the method's
            own options, over the environments' defaults (:data:`vo_gym.settings.DEFAULT_ESTIMATOR_OPTIONS`);
            ``noise_sigma`` (px, default 0.5) is also the noise the features assume. A one-shot
            sampler's adaptive search starts with batches of 4 (``first_batch_size``) doubling to 8
            (``batch_size``) unless given, so that its stop can act after a few hypotheses. An
            in-frame search has batches of ``batch_size`` from the first (``first_batch_size`` is
            refused) and ends at its cap on its best-supported hypothesis (``fail_at_cap=False``,
            accepted; True is refused).
        seed: an integer >= 0 seeding the estimator's own generator, used when :meth:`estimate`
            gets no ``rng`` (restarted by :meth:`reset`).

    Raises:
        ValueError: an unknown sampler name, a missing or unusable file (one line naming it), a bad
            option or one the sampler's kind does not use (naming it and its value).
    """

    def __init__(self, sampler: Any, *, budget: int | None = None, confidence: float | None = None,
                 method: str = "msac", max_hypotheses: int | None = None, batch_size: int | None = None,
                 temperature: float = 1.0, seed: int = 0, **estimator_options: Any) -> None:
        if not _is_seed(seed):
            raise ValueError(f"seed must be an integer >= 0, got {seed!r}")
        if hasattr(sampler, "act") and getattr(sampler, "kind", None) in (ONE_SHOT, IN_FRAME):
            if temperature != 1.0:
                raise ValueError(f"temperature {temperature!r}: the loaded sampler {sampler.name!r} keeps the "
                                 "temperature it was loaded with; pass its name or path to load it with another")
            self.policy = sampler
        else:
            if not isinstance(sampler, (str, os.PathLike)):
                raise ValueError(f"sampler must be a shipped name, a checkpoint path or a loaded sampler, "
                                 f"got {type(sampler).__name__}")
            try:
                self.policy = load_sampler(sampler, temperature=temperature)
            except (FileNotFoundError, CheckpointError, ValueError) as err:
                raise _bad_sampler(sampler, err) from None
        self.kind: str = self.policy.kind
        self.name: str = self.policy.name
        # options that the other kind would use are refused rather than silently ignored
        if self.kind == IN_FRAME and temperature != 1.0:
            raise ValueError(f"temperature {temperature!r}: in-frame sampler {self.name!r} has no temperature "
                             "(it applies to one-shot samplers)")
        if self.kind == ONE_SHOT and max_hypotheses is not None:
            raise ValueError(f"max_hypotheses {max_hypotheses!r}: caps an in-frame search; one-shot sampler "
                             f"{self.name!r} stops adaptively within max_iterations")
        if max_hypotheses is None:
            max_hypotheses = IN_FRAME_CAP
        confidence_given = confidence is not None
        if confidence is None:
            confidence = DEFAULT_CONFIDENCE[self.kind]
        if isinstance(confidence, bool) or not isinstance(confidence, (int, float)) or not 0 < confidence < 1:
            raise ValueError(f"confidence must be in (0, 1), got {confidence!r}")
        self.confidence = float(confidence)
        for label, value, allow_none in (("budget", budget, True), ("max_hypotheses", max_hypotheses, False),
                                         ("batch_size", batch_size, True)):
            if value is None and allow_none:
                continue
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
                raise ValueError(f"{label} must be {'None or ' if allow_none else ''}an integer >= 1, got {value!r}")
        self.budget = None if budget is None else int(budget)
        if self.budget is not None and confidence_given:
            raise ValueError(f"confidence {confidence!r}: with budget={self.budget} {self.name!r} draws exactly that "
                             "many hypotheses and no stop runs for a confidence to set (budget=None stops at it)")
        self.method = method
        spec = self._spec = method_spec(method)
        if spec.build is None:
            raise ValueError(f"method {method!r} does not sample hypotheses, so a learned sampler has no role in it; "
                             "pick a sampling method (e.g. 'msac')")
        options = {**DEFAULT_ESTIMATOR_OPTIONS, **estimator_options}
        # the environments' recipe and this estimator's own settings, only where the method reads them
        # (validate_options refuses the caller's own that it would not read)
        own = set(DEFAULT_ESTIMATOR_OPTIONS) | {"first_batch_size"} | ({"batch_size"} if batch_size is None else set())
        own -= set(estimator_options)
        if self.kind == ONE_SHOT:
            if self.budget is None:
                options.setdefault("first_batch_size", 4)
                options.setdefault("batch_size", 8 if batch_size is None else batch_size)
                options["confidence"] = self.confidence
            else:
                options["batch_size"] = self.budget if batch_size is None else batch_size
            options["budget"] = self.budget
            options = drop_unread(method, options, among=own, order=False)
            self._shared, _ = validate_options(method, options, priors=True)
            self._options = {k: v for k, v in options.items() if k != "noise_sigma"}
        else:
            if spec.inputs in ("priors", "order"):
                needs = "priors= (inlier probabilities)" if spec.inputs == "priors" else "order= (a PROSAC order)"
                raise ValueError(f"method {method!r} needs {needs} from its caller; in-frame sampler {self.name!r} "
                                 "draws from its own weights batch by batch and passes none: pick a method that "
                                 "samples without them (e.g. 'msac', 'mlesac' or 'probabilistic')")
            # the search's own stopping rule is replaced by the sampler's stop under the cap: the options
            # of that rule which have no counterpart here are refused rather than ignored
            if "first_batch_size" in estimator_options:
                raise ValueError(f"first_batch_size {estimator_options['first_batch_size']!r}: in-frame sampler "
                                 f"{self.name!r} draws batch_size hypotheses a batch from the first (default "
                                 f"{IN_FRAME_BATCH}, its training batch)")
            options = drop_unread(method, options, among=own, order=False)
            self._shared, self._extra = validate_options(method, options)
            if "fail_at_cap" in estimator_options and self._shared.fail_at_cap:
                raise ValueError(f"fail_at_cap {estimator_options['fail_at_cap']!r}: in-frame sampler {self.name!r} "
                                 "ends a search that reaches its cap on the best-supported hypothesis, as it was "
                                 "trained to; only fail_at_cap=False applies")
            self._shared = replace(self._shared, fail_at_cap=False, confidence=self.confidence)  # what the search does
            self.batch_size = IN_FRAME_BATCH if batch_size is None else int(batch_size)
            cap = int(max_hypotheses)
            if "max_iterations" in estimator_options:  # given: it caps the stop (its default, 10 000, would not)
                cap = min(cap, self._shared.max_iterations)
            self.max_hypotheses = max(cap, self.budget or 0)
        self.noise_sigma = self._shared.noise_sigma
        self.seed = seed
        self.reset()

    # ------------------------------------------------------------------ state

    def reset(self) -> None:
        """Start a new sequence: forget the previous motion and restart the own generator."""
        self.previous_motion: tuple[np.ndarray, np.ndarray] | None = None
        self._rng = np.random.default_rng(self.seed)

    @property
    def options(self):
        """The :class:`stereovo.estimation.EstimatorOptions` the core runs with."""
        return self._shared

    def __repr__(self) -> str:
        stop = f"budget {self.budget}" if self.budget is not None else f"own stop at {self.confidence:g}"
        return f"LearnedEstimator({self.name!r}, {self.kind}, {self.method}, {stop})"

    # ------------------------------------------------------------------ estimation

    def estimate(self, prev: np.ndarray, curr: np.ndarray, camera: StereoCamera, scores: np.ndarray | None = None,
                 rng: np.random.Generator | int | None = None) -> LearnedMotionEstimate:
        """The motion ``x_k = R x_{k-1} + t`` between two stereo frames, sampled by the learned sampler.

        Args:
            prev, curr: ``(N, 4)`` stereo measurements ``(uL, vL, uR, vR)`` in pixels at k-1 and k;
                row i of both is one putative match. Any N.
            camera: the rectified :class:`stereovo.StereoCamera`.
            scores: ``(N,)`` match scores in [0, 1], higher = better (e.g. a descriptor ratio test
                mapped to (0, 1)). None: no score is known, and every row gets the uninformative
                score :data:`UNINFORMATIVE_SCORE` and the mid rank 0.5; the samplers were trained
                with scores of ROC AUC 0.6-0.75, so they lose that signal and rely on geometry
                alone (and, with more than 256 matches, the rigid-consistency anchors are the
                first 256 rows instead of the best-scored ones).
            rng: a ``numpy.random.Generator`` or a seed (int >= 0) for this call's draws; None uses the
                estimator's own generator (``seed``; so the same calls after :meth:`reset` give the
                same estimates).

        Returns:
            A :class:`LearnedMotionEstimate`: the fields and post-conditions of
            :func:`stereovo.estimate_motion`'s result (identity motion and ``status="failed: ..."``
            on a hopeless frame, never an exception; rows without depth are never sampled, never
            inliers, and named in ``unusable``; ``covariance`` on success; ``time_s`` the whole
            call: features, network and search), plus ``sampler`` and ``sampler_kind``. A
            successful estimate becomes the previous motion of the next call.

        Raises:
            ValueError: malformed input (shapes, mismatched N, complex or non-numeric values, scores of
                the wrong shape, scores outside [0, 1] or not finite, an ``rng`` that is neither a
                Generator nor a seed); NaN and inf measurement rows are unusable rows, not errors.
        """
        start = time.perf_counter()
        problem = StereoProblem.build(prev, curr, camera, self.noise_sigma, self._shared.min_disparity_sigmas)
        generator = self._rng if rng is None else as_generator(rng)
        features = match_features(problem.prev, problem.curr, camera, scores, self.noise_sigma,
                                  self.previous_motion, problem=problem)
        if self.kind == ONE_SHOT:
            estimate = self._one_shot(problem, features, generator)
        else:
            estimate = self._in_frame(problem, features, generator)
        estimate.time_s = time.perf_counter() - start
        if estimate.ok:
            self.previous_motion = (estimate.rotation, estimate.translation)
        return LearnedMotionEstimate.of(estimate, self.name, self.kind)

    def _one_shot(self, problem: StereoProblem, features: np.ndarray, rng: np.random.Generator) -> MotionEstimate:
        usable = problem.usable_mask
        if np.count_nonzero(usable) < SAMPLE_SIZE:
            priors = np.ones(problem.n)  # the core reports the frame as failed, naming the usable rows
        else:
            priors = self.policy.weights(features, usable)
        return estimate_problem(problem, method=self.method, priors=priors, rng=rng, **self._options)

    def _in_frame(self, problem: StereoProblem, features: np.ndarray, rng: np.random.Generator) -> MotionEstimate:
        sub, rows = problem.usable_subproblem()
        need = max(SAMPLE_SIZE, self._shared.min_inliers)
        unusable = ~problem.usable_mask
        if sub.n < need:
            what = "correspondences" if rows is None else "usable correspondences"
            detail = f"{sub.n}" if rows is None else f"{sub.n} of {problem.n} usable"
            return MotionEstimate(np.eye(3), np.zeros(3), np.zeros(problem.n, dtype=bool),
                                  f"failed: too few {what} ({detail}, need {need})", 0, 0, 0, 0.0, self.method,
                                  unusable=unusable)
        search = InFrameSearch(sub, features if rows is None else features[rows], self._spec, self._shared,
                               self.max_hypotheses, self.previous_motion, rng, extra=self._extra)
        limit = self.max_hypotheses if self.budget is None else self.budget
        while True:
            action = self.policy.act(search.observation())
            # the stop belief against this estimator's confidence (a shared policy keeps its own)
            stop = self.budget is None and self.policy.last_stop_belief >= self.confidence
            batch = min(self.batch_size, limit - search.drawn)
            _, _, done = search.step(np.asarray(action[:-1], dtype=np.float64), stop, batch)
            if done or search.drawn >= limit:
                break
        return search.finish(self.method).on_all_rows(sub, rows, problem.n)

    def estimate_sequence(self, frames, rng: np.random.Generator | int | None = None) -> list[LearnedMotionEstimate]:
        """Estimates for consecutive frame pairs ``[(prev, curr, camera, scores), ...]`` of one
        sequence, after a :meth:`reset`; one generator for all of them."""
        self.reset()
        generator = self._rng if rng is None else as_generator(rng)
        return [self.estimate(prev, curr, camera, scores, rng=generator) for prev, curr, camera, scores in frames]

