"""LO-RANSAC's local optimisation (Chum, Matas & Kittler 2003; Lebeda, Matas & Chum 2012, LO+).

Run by the loop on every new best-so-far model (docs/algorithms.md, `lo-ransac`):

1. ``I_k`` = inliers of the new best at the base gate theta (skip when ``|I_k| < 2 s``).
2. Inner RANSAC: ``r`` non-minimal samples of size ``min(|I_k| / 2, 12)`` drawn from ``I_k``,
   each fitted by least squares, all scored on every correspondence.
3. Iterative least squares with a shrinking gate from the best inner model and from
   the original: ``theta_j = K theta - j (K - 1) theta / L``, j = 0..L; at each step refit
   on the points with residual below ``theta_j`` (at most ``fit_cap`` of them, a random subset,
   LO+'s bound on the cost).
4. The best of all these models replaces the input only if it scores higher, so the best
   score never drops.

"Least squares" here is the stereo reprojection error of the chosen points
(Kabsch start, then batched Gauss-Newton steps), the criterion in which pixel
noise is isotropic (docs/algorithms.md, the `polish` enhancement); candidates are scored with the
loop's own quality (MSAC for the ``lo-ransac`` recipe, as in LO+). Every
inner sample and every shrinking-gate branch is fitted in one batched call.

This module also declares the ``lo_*`` options (shared with ``usac``) and registers ``lo-ransac``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from stereovo.estimation.estimator_options import MAX_COUNT
from stereovo.estimation.recipes import REPROJECTION_READS, base_components, reprojection_judge
from stereovo.estimation.registry import declare_options, register_method
from stereovo.estimation.roles.reprojection import gauss_newton_steps
from stereovo.estimation.roles.scoring import TruncatedQuadratic
from stereovo.estimation.roles.solvers import SAMPLE_SIZE, kabsch_batch
from stereovo.estimation.roles.verification import ScoringContext
from stereovo.options import Integer, Number


def _fit_subsets(ctx: ScoringContext, idx: np.ndarray, weights: np.ndarray, R0, t0, iterations: int):
    """Least-squares motions ``(H, 3, 3), (H, 3)`` on the rows ``idx (H, M)`` weighted 0/1 by ``weights (H, M)``.

    ``R0 = None`` starts from a weighted Kabsch fit on the triangulated points.
    """
    p = ctx.problem
    X, Y = p.points_prev[idx], p.points_curr[idx]
    if R0 is None:
        R0, t0 = kabsch_batch(X, Y, weights)
    R, t, _ = gauss_newton_steps(p.camera, R0, t0, X, Y, p.prev[idx], p.curr[idx], weights=weights, iterations=iterations)
    return R, t


@dataclass(frozen=True)
class InnerRansacLO:
    """LO+ local optimiser (see module docstring).

    Args:
        inner_iterations: r, inner RANSAC samples.
        sample_cap: largest non-minimal sample.
        threshold_multiplier: K, the first gate of the shrinking sequence is K theta.
        steps: L, gate reductions from K theta to theta.
        fit_cap: most points in one least-squares fit (random subset beyond it).
        fit_iterations: Gauss-Newton steps per fit.
    """

    inner_iterations: int = 10
    sample_cap: int = 12
    threshold_multiplier: float = 3.0
    steps: int = 4
    fit_cap: int = 84
    fit_iterations: int = 3
    subsumed_by_refinement: bool = False  # its inner RANSAC searches; the refinement does not
    # this run's counts (a recipe builds its optimiser per estimate); mutable inside the frozen class
    counts: dict = field(
        default_factory=lambda: {"lo_runs": 0, "lo_skipped": 0, "lo_improved": 0, "lo_checks": 0},
        repr=False, compare=False,
    )

    def __post_init__(self) -> None:
        # The estimator's option contract (stereovo.options), under the names the methods take.
        for field, rule in (
            ("inner_iterations", Integer(low=1)),
            ("sample_cap", Integer(low=SAMPLE_SIZE + 1)),
            ("threshold_multiplier", Number(low=1.0)),
            ("steps", Integer(low=1)),
            ("fit_cap", Integer(low=SAMPLE_SIZE)),
            ("fit_iterations", Integer(low=0)),
        ):
            object.__setattr__(self, field, rule.check(f"lo_{field}", getattr(self, field)))

    def improve(self, ctx: ScoringContext, R: np.ndarray, t: np.ndarray, inliers: np.ndarray, score: float,
                rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, int]:
        """Better ``(R, t, inliers, score)`` or the input unchanged, and the point checks spent."""
        members = np.flatnonzero(inliers)
        n = ctx.problem.n
        if members.size < 2 * SAMPLE_SIZE:
            self.counts["lo_skipped"] += 1
            return R, t, inliers, score, 0
        self.counts["lo_runs"] += 1
        checks = 0
        candidates_R, candidates_t, candidates_sq = [], [], []

        # Step 2: inner RANSAC on non-minimal samples of the consensus, all r at once.
        size = min(members.size // 2, self.sample_cap)
        r = self.inner_iterations
        keys = rng.random((r, members.size))
        idx = members[np.argpartition(keys, size - 1, axis=1)[:, :size]]  # (r, size) distinct per row
        R_in, t_in = _fit_subsets(ctx, idx, np.ones(idx.shape), None, None, self.fit_iterations)
        sq_in = ctx.residuals(R_in, t_in)
        checks += r * n
        q_in = ctx.quality.score(sq_in, ctx.threshold_sq)
        best_inner = int(np.argmax(q_in))
        candidates_R.append(R_in)
        candidates_t.append(t_in)
        candidates_sq.append(sq_in)

        # Step 3: iterative least squares with a shrinking gate, from the best inner model and the input.
        R_cur = np.stack([R_in[best_inner], R])
        t_cur = np.stack([t_in[best_inner], t])
        sq_cur = np.stack([sq_in[best_inner], ctx.residuals(R[None], t[None])[0]])
        checks += n
        K, L = float(self.threshold_multiplier), int(self.steps)
        for j in range(L + 1):
            gate_sq = ((K - j * (K - 1) / L) ** 2) * ctx.threshold_sq
            inside = sq_cur < gate_sq  # (2, N)
            if np.any(np.count_nonzero(inside, axis=1) < SAMPLE_SIZE):
                break
            # LO+: at most fit_cap points per fit, a random subset of those inside the gate.
            keys = np.where(inside, rng.random(inside.shape), np.inf)
            m = min(self.fit_cap, n)
            idx = np.argpartition(keys, m - 1, axis=1)[:, :m]
            weights = np.isfinite(np.take_along_axis(keys, idx, axis=1)).astype(float)
            R_cur, t_cur = _fit_subsets(ctx, idx, weights, R_cur, t_cur, self.fit_iterations)
            sq_cur = ctx.residuals(R_cur, t_cur)
            checks += 2 * n
            candidates_R.append(R_cur)
            candidates_t.append(t_cur)
            candidates_sq.append(sq_cur)

        all_R = np.concatenate(candidates_R)
        all_t = np.concatenate(candidates_t)
        all_sq = np.concatenate(candidates_sq)
        scores = ctx.quality.score(all_sq, ctx.threshold_sq)
        best = int(np.argmax(scores))
        self.counts["lo_checks"] += checks
        if scores[best] > score:
            self.counts["lo_improved"] += 1
            return all_R[best], all_t[best], all_sq[best] < ctx.threshold_sq, float(scores[best]), checks
        return R, t, inliers, score, checks

    def counters(self) -> dict[str, int | float]:
        """``lo_runs`` (LO run on a new best), ``lo_skipped`` (fewer than 2 s inliers), ``lo_improved``
        (the result replaced the best), ``lo_checks`` (point checks spent in LO)."""
        return dict(self.counts)


LO_OPTIONS = ("lo_inner_iterations", "lo_sample_cap", "lo_threshold_multiplier", "lo_steps")
declare_options({
    "lo_inner_iterations": Integer(low=1, high=MAX_COUNT, default=InnerRansacLO.inner_iterations),
    "lo_sample_cap": Integer(low=4, high=MAX_COUNT, default=InnerRansacLO.sample_cap),
    "lo_threshold_multiplier": Number(low=1.0, high=1e6, default=InnerRansacLO.threshold_multiplier),
    "lo_steps": Integer(low=1, high=MAX_COUNT, default=InnerRansacLO.steps),
})  # shared with usac


LO_READS = dataclasses.replace(REPROJECTION_READS, local="own")
"""``lo-ransac``'s: the reprojection judge's reads, with LO+ on every new best whatever ``local_refit`` says."""


def inner_ransac_lo(extra: dict) -> InnerRansacLO:
    """LO+ with the ``lo_*`` options of ``extra``."""
    return InnerRansacLO(
        inner_iterations=extra["lo_inner_iterations"], sample_cap=extra["lo_sample_cap"],
        threshold_multiplier=float(extra["lo_threshold_multiplier"]), steps=extra["lo_steps"],
    )


@register_method(
    "lo-ransac",
    "MSAC with LO+ on every new best: inner RANSAC on non-minimal samples, shrinking-gate least squares",
    "Chum, Matas & Kittler 2003; Lebeda, Matas & Chum 2012",
    extra_options=LO_OPTIONS,
    reads=LO_READS,
)
def _build_lo_ransac(problem, options, priors, order, extra):
    components = base_components(problem, options, priors, order, *reprojection_judge(options, TruncatedQuadratic()))
    components.local_optimizer = inner_ransac_lo(extra)  # replaces the light consensus refit
    return components
