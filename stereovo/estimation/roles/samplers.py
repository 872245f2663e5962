"""Minimal-sample generators: uniform, prior-weighted (guided) and PROSAC.

A sampler hands out batches ``(B, 3)`` of three *distinct* correspondence
indices; all randomness comes from the generator passed to :meth:`draw`.
Priors and orderings are how the Gymnasium agents reach the estimator.
"""

from __future__ import annotations

import functools
import math
from typing import ClassVar, Protocol

import numpy as np

from stereovo.estimation.kernels.verification import weighted_all_inlier_probability
from stereovo.estimation.kernels.sampling import (
    cumulative_weights, distinct_triplets, prior_defects, weighted_triplets,
)
from stereovo.estimation.roles.solvers import SAMPLE_SIZE
from stereovo.estimation.roles.termination import all_inlier_probability as uniform_all_inlier_probability
from stereovo.options import real_array


class Sampler(Protocol):
    n: int

    def draw(self, batch: int, rng: np.random.Generator) -> np.ndarray:
        """``(batch, 3)`` int64 indices, three distinct per row."""
        ...

    def all_inlier_probability(self, inliers: np.ndarray) -> float:
        """Chance that ONE draw of this sampler is all-inlier, given the inlier mask ``(n,)`` bool.

        The adaptive stopping bound uses it (Schoenberger, Larsson & Pollefeys 2025 for uniform draws): a guided sampler that favours
        the inliers stops sooner, one that favours the outliers later, than the uniform bound says.
        """
        ...


def _inlier_mask(inliers: np.ndarray, n: int) -> np.ndarray:
    mask = np.asarray(inliers)
    if mask.shape != (n,) or mask.dtype != bool:
        raise ValueError(f"inliers must be a bool mask of shape ({n},), got {mask.dtype} {mask.shape}")
    return mask


def distinct_uniform_triplets(pool_sizes: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Three distinct indices drawn uniformly from ``range(m)`` for each ``m`` in ``pool_sizes``.

    Exact sampling without replacement in closed form: draw from shrinking ranges and
    shift past the indices already taken, so no rejection loop is needed.
    """
    m = np.ascontiguousarray(pool_sizes, dtype=np.int64)
    return distinct_triplets(rng.random((m.shape[0], 3)), m)


class UniformSampler:
    """Every triplet of distinct correspondences equally likely."""

    # q depends on the inlier count alone (the termination then keeps its cached count formula)
    uniform: ClassVar[bool] = True

    def __init__(self, n: int) -> None:
        if n < SAMPLE_SIZE:
            raise ValueError(f"need at least {SAMPLE_SIZE} correspondences to sample, got {n}")
        self.n = n

    def draw(self, batch: int, rng: np.random.Generator) -> np.ndarray:
        return distinct_uniform_triplets(np.full(batch, self.n), rng)

    def all_inlier_probability(self, inliers: np.ndarray) -> float:
        """``prod_{i<3} (I - i) / (N - i)``: three distinct indices, uniformly."""
        count = int(np.count_nonzero(_inlier_mask(inliers, self.n)))
        return float(uniform_all_inlier_probability(count, self.n))


def validate_priors(priors: np.ndarray, n: int) -> np.ndarray:
    """Check per-correspondence prior weights: shape ``(n,)``, real, finite, >= 0, >= 3 positive.

    Any scale is accepted (``np.full(n, 1e307)``, ``exp`` of logits near 709): the weights'
    sum may overflow, so :func:`normalised_weights` divides by the largest weight first.
    """
    p = real_array("priors", priors, (n,), entries="weights", per="one weight per correspondence",
                   what="an array of real weights")
    nonfinite, minimum, positive = prior_defects(np.ascontiguousarray(p))
    if nonfinite:
        raise ValueError("priors contain NaN or inf")
    if minimum < 0:
        raise ValueError(f"priors must be non-negative, got minimum {minimum}")
    if positive < SAMPLE_SIZE:
        raise ValueError(f"priors need at least {SAMPLE_SIZE} positive weights to draw a minimal sample")
    return p


def normalised_weights(priors: np.ndarray) -> np.ndarray:
    """``priors / sum(priors)`` ``(N,)``, computed without overflow or underflow.

    The direct quotient is kept whenever the sum is a finite normal number (so draws stay bit
    for bit what they were); otherwise the weights are first divided by the largest one, the
    log-space normalisation ``exp(log p_i - max_j log p_j)``. A positive weight more than ~1e308
    times smaller than the largest would then round to zero; it keeps the smallest normal
    weight instead, so it stays drawable (the sampler needs three positive weights).
    """
    p = np.asarray(priors, dtype=float)
    with np.errstate(over="ignore"):  # an overflowing sum is the case handled below
        total = float(np.sum(p))
    tiny = np.finfo(float).tiny
    direct = bool(np.isfinite(total) and total >= tiny)
    w = p / total if direct else p / np.max(p)
    lost = (p > 0) & (w < tiny)
    if direct and not np.any(lost):
        return w
    w[lost] = tiny
    return w / np.sum(w)


class WeightedSampler:
    """Guided sampling (Tordoff & Murray): P(i) proportional to ``priors[i]``.

    The three indices are drawn one after another without replacement,
    renormalising each time, by inverting the cumulative weights with the points
    already drawn cut out: three uniforms and a few binary searches per sample,
    in one compiled pass over the batch. :meth:`log_probability` gives the log-probability of
    the ordered draw, which the policy-gradient trainer differentiates.
    """

    def __init__(self, priors: np.ndarray) -> None:
        if np.ndim(priors) != 1:
            raise ValueError(f"priors must be a 1-D array, one weight per correspondence, got shape {np.shape(priors)}")
        self.priors = validate_priors(priors, len(priors))
        self.n = self.priors.shape[0]
        # the quotient, the cumulative sums and the equal-weight test in one compiled pass; weights
        # whose sum overflows or underflows take normalised_weights' careful path
        w, cdf, before, equal, n_positive, direct = cumulative_weights(
            np.ascontiguousarray(self.priors, dtype=float), np.finfo(float).tiny
        )
        if not direct:
            w = normalised_weights(self.priors)
            positive = w[w > 0]
            equal, n_positive = bool(np.all(positive == positive[0])), int(positive.size)
            cdf = np.cumsum(w)
            before = np.concatenate([[0.0], cdf[:-1]])
        self._w = w
        # Equal positive weights: uniform sampling over them, whose q is the count formula exactly.
        self._equal_weights = bool(equal)
        self._n_positive = int(n_positive)
        self._cdf = cdf  # inclusive: mass of [0, i]
        self._before = before  # exclusive: mass of [0, i)

    @property
    def weights(self) -> np.ndarray:
        """``(N,)`` read-only: the chance of each correspondence to be drawn first, ``priors / sum(priors)``
        as :func:`normalised_weights` computes it (a prior that would underflow keeps the smallest normal weight)."""
        view = self._w.view()
        view.flags.writeable = False
        return view

    def draw(self, batch: int, rng: np.random.Generator) -> np.ndarray:
        w = self._w
        u = rng.random((batch, SAMPLE_SIZE))
        samples, suspect = weighted_triplets(u, w, self._cdf, self._before)
        # Rounding at an interval's edge can land on a drawn or zero-weight index; redo those rows exactly.
        for row in np.flatnonzero(suspect):
            samples[row] = self._draw_exactly(u[row])
        return samples

    def _draw_exactly(self, u: np.ndarray) -> np.ndarray:
        """One ordered draw from explicitly renormalised weights (the rare fix-up path)."""
        w = self._w.copy()
        picked = np.empty(SAMPLE_SIZE, dtype=np.int64)
        for k in range(SAMPLE_SIZE):
            cdf = np.cumsum(w)
            i = int(np.searchsorted(cdf, u[k] * cdf[-1], side="right"))
            positive = np.flatnonzero(w > 0)
            i = i if i < self.n and w[i] > 0 else int(positive[np.argmin(np.abs(positive - i))])
            picked[k] = i
            w[i] = 0.0
        return picked

    def all_inlier_probability(self, inliers: np.ndarray) -> float:
        """Chance that one sequential weighted draw of three is all-inlier, given ``inliers (n,)`` bool.

        ``q = sum over ordered distinct (a, b, c) in I of w_a/W * w_b/(W - w_a) * w_c/(W - w_a - w_b)``,
        summed exactly by a compiled O(|I|^2) routine (the third factor's sum over c is
        ``(W_I - w_a - w_b) / (W - w_a - w_b)``). Equal positive weights give the uniform formula over
        the positive-weight correspondences, bit for bit the uniform sampler's when all are positive.
        """
        mask = _inlier_mask(inliers, self.n)
        if self._equal_weights:
            count = int(np.count_nonzero(mask & (self._w > 0)))
            return float(uniform_all_inlier_probability(count, self._n_positive))
        return float(weighted_all_inlier_probability(np.ascontiguousarray(self._w[mask]),
                                                     np.ascontiguousarray(self._w[~mask]), 1.0))

    def log_probability(self, samples: np.ndarray) -> np.ndarray:
        """Log-probability ``(B,)`` of drawing each ordered triplet sequentially without replacement."""
        picked = self._w[samples]
        taken = np.cumsum(picked, axis=1) - picked
        # The mass left before a pick holds at least the picked point's weight. When 1 - taken rounds
        # below it (0.5 + 0.5 == 1.0 with a third weight of 5e-18), that point is all that is left:
        # its factor is 1 (a floor on the mass left instead made it 5e-18 / 1e-12).
        with np.errstate(invalid="ignore", divide="ignore"):  # the branch np.where discards
            left = np.where(1.0 - taken > picked, np.log1p(-taken), np.log(picked))
        return np.sum(np.log(picked) - left, axis=1)


def prosac_growth(n: int, sample_size: int = SAMPLE_SIZE, t_n: float = 200_000) -> np.ndarray:
    """PROSAC's T'_n for n = 0..N (Chum & Matas 2005); entries below ``sample_size`` are 0.

    ``T_m = T_N prod_{i<m} (m-i)/(N-i)``, ``T_{k+1} = T_k (k+1)/(k+1-m)``,
    ``T'_m = 1``, ``T'_{k+1} = T'_k + ceil(T_{k+1} - T_k)``.

    The recursion is sequential (a cumulative product would round differently and move the
    ceilings), so it runs as a Python loop over n; :func:`shared_prosac_growth` keeps its results.
    """
    m = sample_size
    T = np.zeros(n + 1)
    T_prime = np.zeros(n + 1, dtype=np.int64)
    if n < m:
        return T_prime
    i = np.arange(m)
    T[m] = t_n * np.prod((m - i) / (n - i))
    T_prime[m] = 1
    for k in range(m, n):
        T[k + 1] = T[k] * (k + 1) / (k + 1 - m)
        T_prime[k + 1] = T_prime[k] + int(np.ceil(T[k + 1] - T[k]))
    return T_prime


@functools.lru_cache(maxsize=64)
def shared_prosac_growth(n: int, sample_size: int = SAMPLE_SIZE, t_n: float = 200_000) -> np.ndarray:
    """:func:`prosac_growth` computed once per arguments, as one shared read-only ``(n + 1,)``
    array: the same N recurs on every frame of a sequence, and the loop over n is not free."""
    growth = prosac_growth(n, sample_size, t_n)
    growth.flags.writeable = False
    return growth


def validate_order(order: np.ndarray, n: int) -> np.ndarray:
    """Check a PROSAC ordering: a permutation of ``range(n)``, best correspondence first."""
    o = np.asarray(order)
    if o.shape != (n,) or not np.issubdtype(o.dtype, np.integer):
        raise ValueError(f"order must be an integer array of shape ({n},), got {o.dtype} {o.shape}")
    if not np.array_equal(np.sort(o), np.arange(n)):
        raise ValueError("order must be a permutation of range(N): each correspondence exactly once")
    return o.astype(np.int64)


class ProsacSampler:
    """PROSAC (Chum & Matas 2005): samples from a growing set of top-ranked correspondences.

    Draw t (1-based) uses ``n = min(g(t), n_max)`` with ``g(t) = min{n : T'_n >= t}``.
    While ``t <= T'_n`` the sample is ``u_n`` plus two distinct points of ``U_{n-1}``;
    afterwards it is three distinct points of ``U_n`` (plain RANSAC on ``U_n``).
    ``n_max`` is the termination length n*, which PROSAC's stopping rule may lower; lowering it
    below the current ``n`` moves the draws into ``U_{n*}`` at once (they are then plain RANSAC on
    ``U_{n*}``, the draw count being past ``T'_{n*}``). ``drawn_within(n)`` counts the draws whose
    points all lie in ``U_n``: the samples "drawn from ``U_n``" that PROSAC's maximality counts.
    """

    def __init__(self, order: np.ndarray, t_n: float = 200_000) -> None:
        self.order = validate_order(order, np.asarray(order).shape[0])
        self.n = self.order.shape[0]
        if self.n < SAMPLE_SIZE:
            raise ValueError(f"need at least {SAMPLE_SIZE} correspondences to sample, got {self.n}")
        self.growth = shared_prosac_growth(self.n, SAMPLE_SIZE, t_n)
        self.n_max = self.n
        self.t = 0
        # Draws by their largest rank (0-based), for drawn_within; batches wait in _pending and are
        # folded in now and then (a bincount per batch would cost more than the draw's bookkeeping).
        self._by_largest_rank = np.zeros(self.n, dtype=np.int64)
        self._pending: list[np.ndarray] = []

    def all_inlier_probability(self, inliers: np.ndarray) -> float:
        """Chance that the next draw is all-inlier given ``inliers (n,)`` bool (PROSAC stops by its own rule).

        An anchored draw (``t <= T'_n``) is ``u_n`` plus two of ``U_{n-1}``; a later one three of ``U_n``.
        """
        ranked = _inlier_mask(inliers, self.n)[self.order]
        t = np.array([self.t + 1])
        n = int(self.subset_sizes(t)[0])
        if t[0] <= self.growth[n] and n > SAMPLE_SIZE:
            if not ranked[n - 1]:
                return 0.0
            count = int(np.count_nonzero(ranked[: n - 1]))
            return float(uniform_all_inlier_probability(count, n - 1, SAMPLE_SIZE - 1))
        return float(uniform_all_inlier_probability(int(np.count_nonzero(ranked[:n])), n))

    def required_draws(self, inliers: np.ndarray, confidence: float) -> float:
        """Fewest draws ``T``, counted from the first, after which the chance that none of them was
        all-inlier, ``prod_{t<=T} (1 - q_t)``, is at most ``1 - confidence`` (``inf`` if never).

        PROSAC's draws are not alike: draw t's all-inlier chance ``q_t`` (for ``inliers (n,)`` bool)
        is that of ``u_n`` plus two of ``U_{n-1}`` while anchored, ``n = g(t)``, then of three of
        ``U_{n_max}``. The chance of the *next* draw alone can be 0 (its ``u_n`` an outlier) or 1,
        so a stationary bound on it stops at once or never; the product over the schedule is what
        "confidence of an all-inlier sample" means for a sampler that changes from draw to draw.
        The schedule is the current one (``n_max`` as it stands). Piecewise constant in ``t``: one
        term per prefix size, O(N).
        """
        ranked = _inlier_mask(inliers, self.n)[self.order]
        count = np.concatenate([[0], np.cumsum(ranked)])  # count[n]: inliers among the top n
        top = self.n_max
        sizes = np.arange(SAMPLE_SIZE, top + 1)
        first = self.growth[sizes - 1] + 1  # g(t) = n for t in [T'_{n-1} + 1, T'_n]
        first[0] = 1
        length = np.maximum(self.growth[sizes] - first + 1, 0)
        q = ranked[sizes - 1].astype(float)  # u_n must be an inlier, and two of the n - 1 above it
        for j in range(SAMPLE_SIZE - 1):
            q = q * np.maximum(count[sizes - 1] - j, 0) / np.maximum(sizes - 1 - j, 1)
        q[0] = float(count[SAMPLE_SIZE] == SAMPLE_SIZE)  # n = 3: the top three themselves
        tail_q = float(uniform_all_inlier_probability(int(count[top]), top))  # past T'_{n_max}: three of U_{n_max}
        target = math.log1p(-confidence)
        with np.errstate(divide="ignore"):
            step = np.log1p(-np.minimum(q, 1.0))  # log miss chance per draw, -inf at q = 1
        spent = np.zeros(sizes.size)
        live = length > 0
        spent[live] = step[live] * length[live]
        total = np.cumsum(spent)
        reached = np.flatnonzero(total <= target)
        if reached.size:
            i = int(reached[0])
            before = total[i - 1] if i else 0.0
            if step[i] == -math.inf:
                return float(first[i])
            return float(first[i] - 1 + max(math.ceil((target - before) / step[i]), 1))
        if tail_q <= 0.0:
            return math.inf
        if tail_q >= 1.0:
            return float(self.growth[top] + 1)
        return float(self.growth[top] + max(math.ceil((target - total[-1]) / math.log1p(-tail_q)), 1))

    def subset_sizes(self, t: np.ndarray) -> np.ndarray:
        """``n`` used at draws ``t`` (1-based): ``min(g(t), n_max)``."""
        g = np.searchsorted(self.growth[SAMPLE_SIZE:], t, side="left") + SAMPLE_SIZE
        return np.minimum(np.minimum(g, self.n), self.n_max)

    def draw(self, batch: int, rng: np.random.Generator) -> np.ndarray:
        t = self.t + 1 + np.arange(batch)
        self.t += batch
        n = self.subset_sizes(t)
        anchored = t <= self.growth[n]
        # Anchored draws: u_n plus two distinct points of U_{n-1}; others: three of U_n.
        pool = np.where(anchored, n - 1, n)
        ranks = distinct_uniform_triplets(np.maximum(pool, SAMPLE_SIZE), rng)
        ranks[:, 2] = np.where(anchored, n - 1, ranks[:, 2])
        if np.any(anchored & (pool < SAMPLE_SIZE)):
            # n = 3 at the start: the only sample is the top three.
            first = anchored & (pool < SAMPLE_SIZE)
            ranks[first] = np.arange(SAMPLE_SIZE)
        self._pending.append(ranks)
        if len(self._pending) >= 64:
            self._fold()
        return self.order[ranks]

    def _fold(self) -> None:
        if self._pending:
            self._by_largest_rank += np.bincount(np.concatenate(self._pending).max(axis=1), minlength=self.n)
            self._pending = []

    def drawn_within(self, n: int) -> int:
        """Draws so far whose three points all lie in ``U_n``, the ``n`` top-ranked correspondences."""
        self._fold()
        return int(self._by_largest_rank[: max(int(n), 0)].sum())


class ReplaySampler:
    """Hands out minimal samples drawn elsewhere, in order: the policy-gradient trainer draws
    samples from the network's distribution (recording their log-probabilities) and the
    shared loop fits and scores exactly those."""

    def __init__(self, samples: np.ndarray, n: int) -> None:
        samples = np.asarray(samples, dtype=np.int64)
        if samples.ndim != 2 or samples.shape[1] != SAMPLE_SIZE:
            raise ValueError(f"samples must have shape (M, {SAMPLE_SIZE}), got {samples.shape}")
        if samples.size and (samples.min() < 0 or samples.max() >= n):
            raise ValueError(f"sample indices must lie in [0, {n})")
        self.samples = samples
        self.n = n
        self.position = 0

    def draw(self, batch: int, rng: np.random.Generator) -> np.ndarray:
        if self.position + batch > self.samples.shape[0]:
            raise ValueError(f"replay exhausted: {self.samples.shape[0]} samples, asked for {self.position + batch}")
        out = self.samples[self.position : self.position + batch]
        self.position += batch
        return out
