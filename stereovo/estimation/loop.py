"""The one RANSAC loop: sampler, sample check, solver, verifier, local optimiser, termination, refinement.

Every named method (RANSAC, MSAC, the probabilistic RANSAC, the classical
family, the environment's guided sampling) is a :class:`RansacComponents`
recipe run by :func:`run_ransac`. Hypotheses are drawn, fitted and scored in
vectorised batches; the bookkeeping between batches is the only Python loop.
:class:`RansacSearch` is that loop one batch at a time, so that an agent can
steer the sampler between batches (the adaptive environment) on the very same
search.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from stereovo.estimation.problem import StereoProblem
from stereovo.estimation.roles.refinement import ReprojectionRefiner
from stereovo.estimation.roles.samplers import Sampler
from stereovo.estimation.roles.scoring import Quality, ResidualModel
from stereovo.estimation.roles.solvers import SAMPLE_SIZE, minimal_hypotheses
from stereovo.estimation.roles.verification import FullVerification, ScoringContext, Verifier
from stereovo.geometry import finite_motion


class LocalOptimizer(Protocol):
    """Improves each new best model during the search.

    ``subsumed_by_refinement``: True when the optimiser only refits the model on its consensus,
    which the final refinement repeats; the loop then skips it on a best found in the batch that
    ends the search. An optimiser that searches (Lo-RANSAC's inner RANSAC) leaves it False.
    """

    subsumed_by_refinement: bool

    def improve(self, ctx: ScoringContext, R: np.ndarray, t: np.ndarray, inliers: np.ndarray, score: float,
                rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, int]:
        """Better ``(R, t, inliers, score)`` or the input, and the point checks spent."""
        ...


class SampleCheck(Protocol):
    def accept(self, problem: StereoProblem, samples: np.ndarray) -> np.ndarray:
        """``(H,)`` bool: which of the ``(H, 3)`` samples go on to be fitted."""
        ...


class Termination(Protocol):
    """How many hypotheses the search still needs: ``required`` answers for the best model's inlier
    count (clipped to ``max_iterations``, the cap). A fixed budget sets ``is_budget = True`` (read
    with ``getattr``, default False): its cap is the stop itself, not a limit reached before it."""

    max_iterations: int

    def required(self, n_inliers: int, n: int) -> int: ...


@dataclass
class RansacComponents:
    """A RANSAC variant as a composition of roles (see module docstring).

    Attributes:
        sampler: draws ``(B, 3)`` minimal samples.
        sample_check: optional; removes samples before they are fitted (they still count as
            drawn), e.g. :class:`stereovo.estimation.roles.sample_check.RigidityCheck`.
        residual_model, quality, threshold_sq: how a hypothesis is judged.
        verifier: full scoring or an early-rejection strategy.
        termination: adaptive bound or fixed budget.
        local_optimizer: optional, runs on every new best hypothesis (a mere consensus refit is
            skipped on a best from the batch that ends the search: the refiner does that work).
        refiner: final LM refinement on the inliers; None keeps the best hypothesis as is.
        batch_size: hypotheses fitted and scored per vectorised batch (the largest batch when
            ``first_batch_size`` is set).
        first_batch_size: the first batch's size if smaller than ``batch_size``, after which each
            batch doubles up to ``batch_size``; None for batches of ``batch_size`` throughout.
        polish_iterations: Gauss-Newton steps on each minimal sample's reprojection error.
        runner_up_fraction: None, or from the second batch on, also give the local optimiser the
            batch's best-scoring hypothesis that is not a new best (the runner-up) when its consensus
            holds at least this fraction of the best model's inliers; it replaces the best only if it
            then scores higher (docs/algorithms.md, "The runner-up refit").
        min_inliers: fewer inliers in the best model means "no consensus".
        fail_at_cap: a search that drew ``termination.max_iterations`` hypotheses without its stop
            being met for the returned model's inliers ends in failure ("no confident consensus"),
            one of the two ends Fischler & Bolles give a search whose cap comes first; False returns
            the largest consensus found, the other (docs/algorithms.md, "What "ok" means"). A
            termination with ``is_budget = True`` (a fixed budget) has no stop to meet.
        listeners: objects whose ``on_new_best(inliers, loop_state)`` is called on each new best
            (PROSAC's sampler, SPRT's verifier adapt there); a listener may also define
            ``on_batch(loop_state)``, called after every batch. The termination listens itself,
            after them, where it defines these methods (an adaptive bound reads a guided sampler's
            q on each new best, SPRT's termination counts the draws made under each test): a
            recipe lists only its other listeners (a termination listed among them is called once).
        search_runner: optional ``run(search)`` that advances a fresh :class:`RansacSearch` as its
            steps would, in fewer calls (BANSAC's and ARS's compiled searches); :func:`run_ransac` calls it
            first and then steps whatever it left undone, so a runner that declines does nothing.

    Hooks for cheaper verifiers and adaptive terminations:
        - a verifier with ``uses_samples = True`` gets ``samples=`` ``(H, 3)``, the minimal sample of
          each hypothesis it verifies, so its early checks can skip the sample's own points
          (T(d,d), SPRT: both check points outside the sample, Matas & Chum 2002, 2005);
        - ``termination.required`` is asked again after every batch once a best model exists, so a
          rule whose bound moves between new bests (SPRT's delta estimate) takes effect at once.
    """

    sampler: Sampler
    residual_model: ResidualModel
    quality: Quality
    threshold_sq: float
    termination: Termination
    verifier: Verifier = field(default_factory=FullVerification)
    local_optimizer: LocalOptimizer | None = None
    refiner: ReprojectionRefiner | None = field(default_factory=ReprojectionRefiner)
    batch_size: int = 32
    first_batch_size: int | None = None
    polish_iterations: int = 2
    runner_up_fraction: float | None = None
    min_inliers: int = 6
    fail_at_cap: bool = True
    listeners: list[Any] = field(default_factory=list)
    sample_check: SampleCheck | None = None
    search_runner: Any = None


@dataclass
class RansacReport:
    """What one run of the loop found and what it cost."""

    rotation: np.ndarray
    translation: np.ndarray
    inliers: np.ndarray
    score: float
    status: str
    n_hypotheses: int  # minimal samples drawn (degenerate ones included)
    n_scored: int  # hypotheses that reached verification
    n_point_checks: int  # point-hypothesis residual evaluations, local optimisation included
    n_degenerate: int
    n_local_optimizations: int
    best_found_at: int  # hypotheses drawn when the final best was first found
    n_rejected_samples: int = 0  # samples the sample check removed before fitting
    # The components' own counts (``counters()`` of the sampler, verifier, termination, local
    # optimiser, sample check and refiner, merged by name); a direct runner fills it itself.
    counters: dict = field(default_factory=dict)
    # (residual model, threshold_sq) that selected ``inliers`` under the returned pose: the
    # method's own final judge (:func:`final_report`); None where no model was judged
    gate: tuple | None = None


@dataclass
class LoopState:
    """Read-only view of the loop for listeners and feedback hooks.

    ``samples``: ``(H, 3)`` the minimal samples of the hypotheses just verified (set for
    ``on_hypotheses`` only); ``best_inliers``: ``(N,)`` bool, the best model's consensus so far.
    """

    n_hypotheses: int
    best_score: float
    samples: np.ndarray | None = None
    best_inliers: np.ndarray | None = None


COUNTED_ROLES = ("sampler", "verifier", "termination", "local_optimizer", "sample_check", "refiner")


def component_counters(c: RansacComponents) -> dict[str, int | float]:
    """Merge ``counters()`` of every role that defines it (components are built per run, so the
    counts are this run's); a later role's key overrides an earlier one's."""
    merged: dict[str, int | float] = {}
    for role in COUNTED_ROLES:
        counters = getattr(getattr(c, role), "counters", None)
        if callable(counters):
            merged.update(counters())
    return merged


def local_refit_redundant(c: RansacComponents, drawn: int, best_inliers: np.ndarray, n: int) -> bool:
    """True if the new best's local refit would only repeat the final refinement's work: the
    optimiser just refits on the consensus, a refiner follows, and this batch ends the search."""
    if c.refiner is None or not c.local_optimizer.subsumed_by_refinement:
        return False
    required = c.termination.required(int(np.count_nonzero(best_inliers)), n)
    return drawn >= min(required, c.termination.max_iterations)


class RansacSearch:
    """One run of the loop, one batch at a time: :func:`run_ransac` steps it until the termination
    is met, and the adaptive environment steps it batch by batch with the agent's priors.

    ``step(batch)`` draws, checks, fits and verifies ``batch`` hypotheses (default: the loop's own
    batch schedule), updates the best model and calls the hooks; ``done`` says whether the
    termination is met; ``finish()`` refines the best model and returns the :class:`RansacReport`.
    A sampler that defines ``on_hypotheses(R (H, 3, 3), t (H, 3), inlier_masks (H, N) bool,
    residual_sq (H, N), loop_state)`` gets every verified batch with its full squared residuals
    (uncapped and read-only: kept from the scoring pass where that scored the whole batch, else
    computed for it; counted in ``n_point_checks`` either way) and ``loop_state.samples``.
    """

    def __init__(self, problem: StereoProblem, components: RansacComponents, rng: np.random.Generator) -> None:
        c = self.components = components
        self.problem, self.rng, self.n = problem, rng, problem.n
        self._feedback = getattr(c.sampler, "on_hypotheses", None)
        self.ctx = ScoringContext(problem, c.residual_model, c.quality, c.threshold_sq,
                                  keep_exact=self._feedback is not None)
        self.best_R, self.best_t = np.eye(3), np.zeros(3)
        self.best_inliers = np.zeros(self.n, dtype=bool)
        self.best_score = -np.inf
        self.drawn = self.scored = self.checks = self.degenerate = self.rejected = 0
        self.local_runs = self.found_at = 0
        self.runner_up_runs = self.runner_up_wins = 0
        self.required = c.termination.max_iterations
        self._uses_samples = bool(getattr(c.verifier, "uses_samples", False))
        listening = [*c.listeners, *([] if any(x is c.termination for x in c.listeners) else [c.termination])]
        self._best_listeners = [listener for listener in listening if hasattr(listener, "on_new_best")]
        self._batch_listeners = [listener for listener in listening if hasattr(listener, "on_batch")]
        # An adaptive search starts small (the bound often falls below a full batch at once) and doubles
        # its batches up to batch_size: each batch costs bookkeeping here, as much as several
        # hypotheses, so a long search (high contamination) should take few, large ones.
        self.next_size = min(c.first_batch_size, c.batch_size) if c.first_batch_size else c.batch_size

    @property
    def done(self) -> bool:
        """True once the termination's bound (or its cap) has been drawn."""
        return self.drawn >= self.required

    @property
    def state(self) -> LoopState:
        return LoopState(n_hypotheses=self.drawn, best_score=self.best_score, best_inliers=self.best_inliers)

    def step(self, batch: int | None = None) -> None:
        """Draw and judge one batch: ``batch`` hypotheses, or the loop's schedule capped by the bound."""
        c, ctx, n = self.components, self.ctx, self.n
        if batch is None:
            batch = int(min(self.next_size, self.required - self.drawn))
            self.next_size = min(2 * self.next_size, c.batch_size)
        samples = c.sampler.draw(batch, self.rng)
        self.drawn += batch
        if c.sample_check is not None:
            keep = c.sample_check.accept(self.problem, samples)
            self.rejected += batch - int(np.count_nonzero(keep))
            samples = samples[keep]
        R, t, valid = minimal_hypotheses(self.problem, samples, c.polish_iterations)
        n_valid = int(np.count_nonzero(valid))
        self.degenerate += len(valid) - n_valid
        if n_valid:
            if n_valid < len(valid):
                R, t, samples = R[valid], t[valid], samples[valid]
            if self._uses_samples:
                scores, spent = c.verifier.verify(ctx, R, t, self.rng, samples=samples)
            else:
                scores, spent = c.verifier.verify(ctx, R, t, self.rng)
            self.take_scores(R, t, samples, scores, spent)
        self.end_batch()

    def take_scores(self, R: np.ndarray, t: np.ndarray, samples: np.ndarray, scores: np.ndarray, spent: int) -> None:
        """The rest of a batch's step once its ``H`` valid hypotheses ``(R (H, 3, 3), t (H, 3))`` from
        ``samples (H, 3)`` are scored (``scores (H,)``, ``spent`` point checks): the new best and its
        local refit, the runner-up refit, the sampler's feedback (``probabilistic``'s compiled search,
        :mod:`stereovo.estimation.compiled_search`, writes this out for its components)."""
        c, ctx, n = self.components, self.ctx, self.n
        self.scored += R.shape[0]
        self.checks += spent
        i = int(np.argmax(scores))
        earlier_best = self.best_score > -np.inf
        new_best = bool(scores[i] > self.best_score)
        if new_best:
            self._new_best(R, t, i, float(scores[i]))
        if c.runner_up_fraction is not None and c.local_optimizer is not None and earlier_best:
            self._refit_runner_up(R, t, scores, i if new_best else -1)
        if self._feedback is not None:
            # kept from the scoring pass where it scored the whole batch; counted as before
            residual_sq = ctx.exact_residuals(R, t)
            self.checks += R.shape[0] * n
            state = LoopState(self.drawn, self.best_score, samples=samples, best_inliers=self.best_inliers)
            self._feedback(R, t, residual_sq < c.threshold_sq, residual_sq, state)

    def end_batch(self) -> None:
        """A batch's last part: the batch listeners, then the bound for the best model's support."""
        c, n = self.components, self.n
        if self._batch_listeners:
            state = self.state
            for listener in self._batch_listeners:
                listener.on_batch(state)
        if self.best_score > -np.inf:
            bound = c.termination.required(int(np.count_nonzero(self.best_inliers)), n)
            self.required = min(bound, c.termination.max_iterations)

    def _new_best(self, R: np.ndarray, t: np.ndarray, i: int, score: float) -> None:
        c = self.components
        self.best_R, self.best_t, self.best_score = R[i], t[i], score
        self.best_inliers, computed = self.ctx.inliers_of(R, t, i)
        self.checks += self.n if computed else 0
        self.found_at = self.drawn
        if c.local_optimizer is not None and not local_refit_redundant(c, self.drawn, self.best_inliers, self.n):
            self.best_R, self.best_t, self.best_inliers, self.best_score, spent = c.local_optimizer.improve(
                self.ctx, self.best_R, self.best_t, self.best_inliers, self.best_score, self.rng
            )
            self.local_runs += 1
            self.checks += spent
        state = self.state
        for listener in self._best_listeners:
            listener.on_new_best(self.best_inliers, state)

    def _refit_runner_up(self, R: np.ndarray, t: np.ndarray, scores: np.ndarray, new_best: int) -> None:
        """Refit the batch's best hypothesis other than ``new_best`` (-1: none of the batch) if its
        consensus is near the best's (and at least a minimal sample), and make it the best if the
        refit then scores higher."""
        c = self.components
        if new_best >= 0:
            if scores.shape[0] < 2:
                return
            scores = scores.copy()
            scores[new_best] = -np.inf
        j = int(np.argmax(scores))
        if scores[j] == -np.inf:
            return
        inliers, computed = self.ctx.inliers_of(R, t, j)
        self.checks += self.n if computed else 0
        count = np.count_nonzero(inliers)
        if count < SAMPLE_SIZE or count < c.runner_up_fraction * np.count_nonzero(self.best_inliers):
            return
        R_j, t_j, inliers_j, score_j, spent = c.local_optimizer.improve(
            self.ctx, R[j], t[j], inliers, float(scores[j]), self.rng
        )
        self.runner_up_runs += 1
        self.checks += spent
        if score_j > self.best_score:
            self.runner_up_wins += 1
            self.best_R, self.best_t, self.best_inliers, self.best_score = R_j, t_j, inliers_j, score_j
            self.found_at = self.drawn
            state = self.state
            for listener in self._best_listeners:
                listener.on_new_best(self.best_inliers, state)

    def choose(self, R: np.ndarray, t: np.ndarray, inliers: np.ndarray, score: float) -> None:
        """Make ``(R (3, 3), t (3,), inliers (N,) bool, score)`` the model that ``finish`` refines: a
        caller whose selection differs from the quality's maximum (the adaptive environment's agent
        judges consensus by its own beliefs) picks among the hypotheses it was shown."""
        self.best_R, self.best_t, self.best_inliers, self.best_score = R, t, inliers, float(score)

    def finish(self) -> RansacReport:
        """The final refinement of the best model and the run's report (:func:`final_report`)."""
        c, n = self.components, self.n
        counts = dict(n_hypotheses=self.drawn, n_scored=self.scored, n_point_checks=self.checks,
                      n_degenerate=self.degenerate, n_rejected_samples=self.rejected,
                      n_local_optimizations=self.local_runs + self.runner_up_runs, best_found_at=self.found_at)
        counters = component_counters(c)
        if c.runner_up_fraction is not None:
            counters.update(runner_up_refits=self.runner_up_runs, runner_up_wins=self.runner_up_wins)
        if self.scored == 0:
            reason = "all samples degenerate" if self.rejected == 0 else (
                f"no sample passed the sample check ({self.rejected} of {self.drawn} rejected, "
                f"{self.degenerate} degenerate)"
            )
            return RansacReport(np.eye(3), np.zeros(3), np.zeros(n, dtype=bool), -np.inf, f"failed: {reason}",
                                counters=counters, **counts)
        report = final_report(
            self.problem, self.best_R, self.best_t, self.best_inliers, self.best_score, c.refiner,
            c.residual_model, c.quality, c.threshold_sq, c.min_inliers, counters, **counts,
        )
        return self._unconfirmed(report) if c.fail_at_cap else report

    def _unconfirmed(self, report: RansacReport) -> RansacReport:
        """``report``, or a failure if the search reached its cap before its stop and the returned
        model's inliers do not meet the stop either (its confidence was never reached)."""
        term, n = self.components.termination, self.n
        cap = int(term.max_iterations)
        if report.status != "ok" or getattr(term, "is_budget", False) or self.drawn < cap:
            return report
        count = int(np.count_nonzero(report.inliers))
        # bounds are clipped to the cap: reaching it means the stop asks for at least the cap
        if term.required(count, n) < cap:
            return report
        status = (f"failed: no confident consensus (the cap of {cap} hypotheses came before the stop, "
                  f"which the returned model's {count} inliers of {n} rows do not meet)")
        return dataclasses.replace(report, rotation=np.eye(3), translation=np.zeros(3),
                                   inliers=np.zeros(n, dtype=bool), status=status)


def final_report(
    problem: StereoProblem,
    R: np.ndarray,
    t: np.ndarray,
    inliers: np.ndarray,
    score: float,
    refiner: ReprojectionRefiner | None,
    residual_model: ResidualModel,
    quality: Quality,
    threshold_sq: float,
    min_inliers: int,
    counters: dict,
    **counts: int,
) -> RansacReport:
    """Refine the best model ``(R (3, 3), t (3,))`` with consensus ``inliers (N,)`` and report it.
    ``score`` is the caller's score of it; the model is scored anew under the final gate, so that
    the refinement is compared with it on one scale.

    This is where every method's final model and status are decided (the loop's
    :meth:`RansacSearch.finish` and the direct estimators end here), so the post-condition holds
    for all of them: status ``"ok"`` only if the returned pose is finite and at least
    ``max(min_inliers, 3)`` rows pass the method's own final gate under it, and the returned
    inliers are exactly those rows, selected anew under the returned pose (never carried over
    from an earlier hypothesis). The gate is the refiner's where it carries one (``probabilistic``
    selects its final inliers in pixels), else the method's residual model and threshold.

    The refinement replaces the best model only if its score under that gate, on the same rows,
    is no worse (ties go to the refined pose, the least-squares fit on the same consensus); one
    that diverges (non-finite values) or loses support is rolled back to the model it started
    from (``counters["refine_rolled_back"]``). ``counts``: the :class:`RansacReport` counts; the
    point checks spent here are added to ``n_point_checks``.
    """
    n = problem.n
    gate = None if refiner is None else refiner.gate
    gate_model, gate_sq = (residual_model, threshold_sq) if gate is None else gate
    # The starting model is scored here, under the gate, whatever score the caller holds: a caller
    # that chose the model by its own measure (the in-frame search's agent) passes another scale.
    residual_sq = gate_model.squared(problem, R[None], t[None])[0]
    score = float(quality.score(residual_sq[None], gate_sq)[0])
    checks = n
    if refiner is not None:
        counters = {**counters, "refine_rolled_back": 0}
    if refiner is not None and np.count_nonzero(inliers) >= 3:
        # The core's refiner re-selects from the gate's residuals of the starting model and hands
        # back those of the refined one: the two passes scored here, read instead of computed
        # twice (and counted as the judge spends them, as before). Any other refiner keeps the
        # protocol: residuals in the method's model, or None.
        core = type(refiner) is ReprojectionRefiner
        if core:
            R_new, t_new, _, new_sq = refiner.refine_with_residuals(
                problem, R, t, inliers, residual_model, threshold_sq,
                start_sq=residual_sq if gate is not None else None, gate_residuals=True,
            )
        else:
            R_new, t_new, _, new_sq = refiner.refine_with_residuals(problem, R, t, inliers, residual_model, threshold_sq)
        checks += n * refiner.rounds
        new_score = -np.inf
        if finite_motion(R_new, t_new):
            if new_sq is None or (core and gate is not None):
                checks += n
            if new_sq is None:  # not computed in the gate's model: score anew
                new_sq = gate_model.squared(problem, R_new[None], t_new[None])[0]
            new_score = float(quality.score(new_sq[None], gate_sq)[0])
        if new_score >= score:
            R, t, score, residual_sq = R_new, t_new, new_score, new_sq
        else:
            counters["refine_rolled_back"] = 1
    counts["n_point_checks"] = counts.get("n_point_checks", 0) + checks
    final = np.asarray(residual_sq < gate_sq)
    count = int(np.count_nonzero(final))
    need = max(int(min_inliers), 3)
    if not finite_motion(R, t):
        reason = "the best model is not finite"
    elif count < need:
        reason = f"no consensus (best model has {count} inliers under its final gate, need {need})"
    else:
        return RansacReport(np.array(R, dtype=float), np.array(t, dtype=float), final, score, "ok",
                            counters=counters, gate=(gate_model, gate_sq), **counts)
    return RansacReport(np.eye(3), np.zeros(3), np.zeros(n, dtype=bool), score, f"failed: {reason}",
                        counters=counters, gate=(gate_model, gate_sq), **counts)


def run_ransac(problem: StereoProblem, components: RansacComponents, rng: np.random.Generator) -> RansacReport:
    """Run the RANSAC loop described by ``components`` on ``problem`` until its termination."""
    search = RansacSearch(problem, components, rng)
    if components.search_runner is not None:
        components.search_runner(search)
    while not search.done:
        search.step()
    return search.finish()
