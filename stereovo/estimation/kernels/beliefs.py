"""Compiled belief updates of the belief-driven samplers: BANSAC's log-odds update with its sampling
weights (:mod:`stereovo.estimation.methods.bansac`) and ARS's most-probable-untried draw with the BaySAC
failure update (:mod:`stereovo.estimation.methods.ars`).

Each kernel computes, element for element and in the same order, what the numpy formulation in
those modules' docstrings computes (``np.logaddexp`` as numpy defines it, products left to right,
``np.clip`` as ``min(max(x, lo), hi)``, ``exp`` and ``log`` from the C library), so the draws and
estimates are bit for bit those of the numpy code; ``tests/stereovo/estimation/kernels/test_beliefs.py``
holds them to that numpy code on fixed seeds. (Where the CPU has AVX-512, numpy's own float64 ``exp``
and ``log`` are vectorised and differ from the C library's in the last bit for a few per cent of
arguments; the reference in ``tests/support/belief_samplers.py`` therefore takes the C library's.)

ARS's set of tried samples is an open-addressing hash table of int64 codes ``(a N + b) N + c`` for
the sorted triple ``a < b < c`` (empty slots hold -1), so a lookup costs a few loads instead of a
Python tuple and set probe per candidate.
"""

from __future__ import annotations

import math

import numpy as np

from stereovo.estimation.kernels.base import inline_jit, jit
from stereovo.estimation.kernels.logaddexp import logaddexp

EMPTY = -1  # an unused slot of a tried-sample table


@jit
def bansac_log_odds_update(log_odds, verdicts, log_c, gated_offset, gated_scale, ungated_shift):
    """BANSAC's update of ``log_odds (N,)`` in place from one hypothesis' ``verdicts (N,)`` bool.

    With ``c`` the classification parameter: ``log_c = log c``, ``gated_offset = log 0.2 + log(1 - c)``,
    ``gated_scale = log 0.8 + log(1 - c)``, ``ungated_shift = log(1 - c) - log c`` (the caller's
    scalars, so they round as numpy's did). A gated point gets
    ``logaddexp(log_c + l, gated_offset) - gated_scale``, any other ``l + ungated_shift``.
    Returns the number of gated points.
    """
    gated = 0
    for i in range(log_odds.shape[0]):
        if verdicts[i]:
            log_odds[i] = logaddexp(log_c + log_odds[i], gated_offset) - gated_scale
            gated += 1
        else:
            log_odds[i] = log_odds[i] + ungated_shift
    return gated


@jit
def logistic_beliefs(log_odds):
    """``(N,)`` beliefs ``exp(-logaddexp(0, -l))``: the logistic of the log-odds without overflow."""
    n = log_odds.shape[0]
    out = np.empty(n)
    for i in range(n):
        out[i] = math.exp(-logaddexp(0.0, -log_odds[i]))
    return out


@jit
def cumulative_weights(weights, total):
    """``(w, cdf, before)``: ``weights / total`` and its inclusive and exclusive cumulative sums
    (``np.cumsum`` adds left to right, as here), the arrays :func:`weighted_triplets` inverts."""
    n = weights.shape[0]
    w = np.empty(n)
    cdf = np.empty(n)
    before = np.empty(n)
    running = 0.0
    for i in range(n):
        w[i] = weights[i] / total
        before[i] = running
        running += w[i]
        cdf[i] = running
    return w, cdf, before


# ----------------------------------------------------------------------------- ARS


@inline_jit
def _triple_code(a, b, c, n):
    """The int64 code of the unordered triple ``{a, b, c}`` of indices below ``n``."""
    lo = min(a, min(b, c))
    hi = max(a, max(b, c))
    mid = a + b + c - lo - hi
    return (lo * n + mid) * n + hi


@inline_jit
def _slot(code, mask):
    """First probe position of ``code`` in a table of ``mask + 1`` slots (a multiplicative hash)."""
    return ((code * np.int64(-7046029254386353131)) >> np.int64(20)) & mask


@inline_jit
def _probe(table, code):
    """The slot holding ``code``, or the empty slot where it would go (linear probing)."""
    mask = table.shape[0] - 1
    s = _slot(code, mask)
    while table[s] != code and table[s] != EMPTY:
        s = (s + 1) & mask
    return s


@inline_jit
def _contains(table, code):
    return table[_probe(table, code)] == code


@inline_jit
def _insert(table, code):
    """Add ``code``; returns 1 if it was new, 0 if already there."""
    s = _probe(table, code)
    if table[s] == code:
        return 0
    table[s] = code
    return 1


@jit
def rehashed(table, size):
    """A table of ``size`` slots (a power of two) holding the codes of ``table``."""
    out = np.full(size, EMPTY, dtype=np.int64)
    for x in table:
        if x != EMPTY:
            _insert(out, x)
    return out


@inline_jit
def _top_candidates(p, tie_break, k, top):
    """The ``k`` most probable indices into ``top (k,)``, best first; equal beliefs by the smaller
    ``tie_break`` (``np.lexsort((tie_break, -p))[:k]``)."""
    filled = 0
    for i in range(p.shape[0]):
        pi, ti = p[i], tie_break[i]
        j = filled
        while j > 0:
            q = top[j - 1]
            if pi > p[q] or (pi == p[q] and ti < tie_break[q]):
                j -= 1
            else:
                break
        if j < k:
            last = min(filled, k - 1)
            for m in range(last, j, -1):
                top[m] = top[m - 1]
            top[j] = i
            if filled < k:
                filled += 1


@inline_jit
def _most_probable_untried(p, tie_break, triples, table, top, out):
    """Write into ``out (3,)`` the untried triple of largest ``p_a p_b p_c`` among the
    :data:`CANDIDATES` most probable points (the first such in ``triples``' order on ties), or the
    largest of all when every one was tried."""
    n = p.shape[0]
    k = top.shape[0]
    _top_candidates(p, tie_break, k, top)
    best, best_value = -1, 0.0
    fallback, fallback_value = -1, 0.0
    for j in range(triples.shape[0]):
        t0, t1, t2 = triples[j, 0], triples[j, 1], triples[j, 2]
        if t0 >= k or t1 >= k or t2 >= k:
            continue
        a, b, c = top[t0], top[t1], top[t2]
        value = p[a] * p[b] * p[c]
        if fallback < 0 or value > fallback_value:
            fallback, fallback_value = j, value
        if (best < 0 or value > best_value) and not _contains(table, _triple_code(a, b, c, n)):
            best, best_value = j, value
    j = best if best >= 0 else fallback
    out[0], out[1], out[2] = top[triples[j, 0]], top[triples[j, 1]], top[triples[j, 2]]


@jit
def ars_next(p, tie_break, triples, table, k):
    """``(3,)`` the sample ARS would draw next from beliefs ``p (N,)`` (nothing is changed)."""
    out = np.empty(3, dtype=np.int64)
    _most_probable_untried(p, tie_break, triples, table, np.empty(k, dtype=np.int64), out)
    return out


@jit
def ars_draw(p, tie_break, triples, table, k, batch, floor):
    """Draw ``batch`` ARS samples, each assumed to fail: after each, the BaySAC failure update of
    its three beliefs in ``p (N,)``, in place, clipped into ``[floor, 1 - floor]``; each sample's
    code goes into ``table`` (which must have room: the caller keeps it under half full).

    Returns ``(samples (batch, 3), codes (batch,), before (batch, 3) the beliefs before each
    update, new_codes)`` with ``new_codes`` the number of codes added to the table.
    """
    n = p.shape[0]
    samples = np.empty((batch, 3), dtype=np.int64)
    codes = np.empty(batch, dtype=np.int64)
    before = np.empty((batch, 3))
    top = np.empty(k, dtype=np.int64)
    row = np.empty(3, dtype=np.int64)
    added = 0
    for r in range(batch):
        _most_probable_untried(p, tie_break, triples, table, top, row)
        a, b, c = row[0], row[1], row[2]
        code = _triple_code(a, b, c, n)
        added += _insert(table, code)
        codes[r] = code
        pa, pb, pc = p[a], p[b], p[c]
        before[r, 0], before[r, 1], before[r, 2] = pa, pb, pc
        everyone = pa * pb * pc
        denominator = max(1.0 - everyone, 1e-300)
        p[a] = min(max(pa * (1.0 - everyone / pa) / denominator, floor), 1.0 - floor)
        p[b] = min(max(pb * (1.0 - everyone / pb) / denominator, floor), 1.0 - floor)
        p[c] = min(max(pc * (1.0 - everyone / pc) / denominator, floor), 1.0 - floor)
        samples[r, 0], samples[r, 1], samples[r, 2] = a, b, c
    return samples, codes, before, added


@jit
def ars_feedback(p, samples, support, pending_codes, pending_before, best_support):
    """Undo the assumed failure of every verified sample that raised the best support.

    ``samples (H, 3)`` and ``support (H,)``: the verified hypotheses in order; ``pending_codes
    (P,)`` and ``pending_before (P, 3)``: every draw since the last feedback, in order. As a
    dictionary from code to its latest draw's beliefs that each verified sample pops: a sample
    whose code is pending and that raises the best support gets that latest draw's beliefs back
    (in place in ``p``). Returns ``(best_support, successes)``.
    """
    n = p.shape[0]
    popped = np.zeros(pending_codes.shape[0], dtype=np.bool_)
    successes = 0
    for h in range(samples.shape[0]):
        a, b, c = samples[h, 0], samples[h, 1], samples[h, 2]
        code = _triple_code(a, b, c, n)
        latest = -1
        for r in range(pending_codes.shape[0] - 1, -1, -1):
            if pending_codes[r] == code:
                if not popped[r]:
                    latest = r
                break
        if latest >= 0:
            for r in range(pending_codes.shape[0]):
                if pending_codes[r] == code:
                    popped[r] = True
        if support[h] > best_support:
            best_support = support[h]
            if latest >= 0:
                p[a], p[b], p[c] = pending_before[latest, 0], pending_before[latest, 1], pending_before[latest, 2]
                successes += 1
    return best_support, successes


# ----------------------------------------------------------------------------- BANSAC's draw arrays


PAIRWISE_BLOCK = 128  # numpy's PW_BLOCKSIZE


@inline_jit
def _block_sum(a, start, n):
    """numpy's sum of a block of at most :data:`PAIRWISE_BLOCK` entries: eight running sums."""
    if n < 8:
        res = 0.0
        for i in range(start, start + n):
            res += a[i]
        return res
    r0, r1, r2, r3 = a[start], a[start + 1], a[start + 2], a[start + 3]
    r4, r5, r6, r7 = a[start + 4], a[start + 5], a[start + 6], a[start + 7]
    i = 8
    while i < n - (n % 8):
        j = start + i
        r0 += a[j]
        r1 += a[j + 1]
        r2 += a[j + 2]
        r3 += a[j + 3]
        r4 += a[j + 4]
        r5 += a[j + 5]
        r6 += a[j + 6]
        r7 += a[j + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[start + i]
        i += 1
    return res


@inline_jit
def _pairwise_sum(a, start, n):
    """numpy's pairwise summation of ``a[start:start + n]`` (``np.sum`` of a contiguous float64
    array): blocks of at most :data:`PAIRWISE_BLOCK`, halves (cut at a multiple of 8) added as
    ``left + right``. Walked with an explicit stack, since numba cannot cache a recursive function."""
    if n <= PAIRWISE_BLOCK:
        return _block_sum(a, start, n)
    # frames: (start, n, stage) with stage 0 = left half pending, 1 = right half pending
    starts = np.empty(64, dtype=np.int64)
    sizes = np.empty(64, dtype=np.int64)
    stages = np.empty(64, dtype=np.int64)
    lefts = np.empty(64)
    depth = 0
    starts[0], sizes[0], stages[0] = start, n, 0
    result = 0.0
    while depth >= 0:
        s, m = starts[depth], sizes[depth]
        if m <= PAIRWISE_BLOCK:
            result = _block_sum(a, s, m)
            depth -= 1
        else:
            half = m // 2
            half -= half % 8
            if stages[depth] == 0:
                stages[depth] = 1
                depth += 1
                starts[depth], sizes[depth], stages[depth] = s, half, 0
                continue
            if stages[depth] == 1:
                lefts[depth] = result
                stages[depth] = 2
                depth += 1
                starts[depth], sizes[depth], stages[depth] = s + half, m - half, 0
                continue
            result = lefts[depth] + result
            depth -= 1
    return result


@jit
def numpy_sum(a):
    """``np.sum(a)`` for a contiguous float64 ``a (N,)``, bit for bit (numpy's pairwise summation)."""
    return _pairwise_sum(a, 0, a.shape[0])


SURE_LOG_ODDS = 40.0  # |log-odds| beyond which the belief's weight is known without the logistic (see below)
EDGE_GUARD = 1e-9  # a product levels * p this close to an integer is rounded exactly


@inline_jit
def _belief(log_odds):
    return math.exp(-logaddexp(0.0, -log_odds))


@inline_jit
def discretised_weight(log_odds, levels):
    """One point's weight ``max(ceil(levels p), 1)`` for its log-odds, as :func:`bansac_draw_arrays` takes it."""
    if log_odds < -SURE_LOG_ODDS:
        return 1.0
    if log_odds > SURE_LOG_ODDS:
        return levels
    scaled = levels / (1.0 + math.exp(-log_odds))
    k = math.ceil(scaled)
    if k - scaled < EDGE_GUARD or scaled - (k - 1.0) < EDGE_GUARD:
        k = math.ceil(levels * _belief(log_odds))
    return max(k, 1.0)


@jit
def bansac_draw_arrays(log_odds, discretised, levels, floor):
    """The sampling weights of BANSAC's beliefs and what :func:`weighted_triplets` inverts.

    Weights ``max(ceil(levels p), 1)`` (``discretised``) or ``max(p, floor)``, with ``p`` the logistic
    :func:`logistic_beliefs`; returns ``(weights, w, cdf, before)``, ``w`` the weights over their
    numpy sum. The discretised weights skip the logistic where it cannot matter: past
    :data:`SURE_LOG_ODDS` the belief is within 1e-17 of 0 or 1 (weight 1 or ``levels``), and where
    ``1 / (1 + exp(-l))`` (within a few ulps of ``p``) is more than :data:`EDGE_GUARD` from a
    rounding edge its ceiling is the exact one's; only the rest take the exact logistic.
    """
    n = log_odds.shape[0]
    weights = np.empty(n)
    for i in range(n):
        if discretised:
            weights[i] = discretised_weight(log_odds[i], levels)
        else:
            weights[i] = max(_belief(log_odds[i]), floor)
    w, cdf, before = cumulative_weights(weights, _pairwise_sum(weights, 0, n))
    return weights, w, cdf, before
