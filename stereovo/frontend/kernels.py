"""Compiled kernels of the front end: candidate pairs in a window, descriptor distances, the best
two candidates per keypoint, and subpixel refinement by patch differences.

Matching is restricted to geometric windows (a row band for stereo, a square for the temporal
match), so the work is the candidate pairs, not all pairs: keypoints of the second image are
sorted by row once and each keypoint of the first scans only the rows of its window.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def window_pairs(pa, pb, order_b, vb_sorted, v_tol, du_lo, du_hi):
    """Candidate pairs ``(ia, jb)`` with ``|vb - va| <= v_tol`` and ``du_lo <= ua - ub <= du_hi``.

    Args:
        pa: ``(Na, 2)`` positions ``(u, v)`` (px) in the first image.
        pb: ``(Nb, 2)`` positions in the second image.
        order_b: ``(Nb,)`` the indices of ``pb`` sorted by v; ``vb_sorted`` those v's.
    Returns:
        ``ia (P,)``, ``jb (P,)`` int64, grouped by ``ia``.
    """
    na = pa.shape[0]
    starts = np.searchsorted(vb_sorted, pa[:, 1] - v_tol, side="left")
    stops = np.searchsorted(vb_sorted, pa[:, 1] + v_tol, side="right")
    count = 0
    for i in range(na):
        for s in range(starts[i], stops[i]):
            du = pa[i, 0] - pb[order_b[s], 0]
            if du_lo <= du <= du_hi:
                count += 1
    ia = np.empty(count, np.int64)
    jb = np.empty(count, np.int64)
    c = 0
    for i in range(na):
        for s in range(starts[i], stops[i]):
            j = order_b[s]
            du = pa[i, 0] - pb[j, 0]
            if du_lo <= du <= du_hi:
                ia[c] = i
                jb[c] = j
                c += 1
    return ia, jb


@njit(cache=True, nogil=True, inline="always")
def _popcount64(x):
    # SWAR bit count (no popcount intrinsic in numba; LLVM turns this idiom into one instruction).
    x = x - ((x >> np.uint64(1)) & np.uint64(0x5555555555555555))
    x = (x & np.uint64(0x3333333333333333)) + ((x >> np.uint64(2)) & np.uint64(0x3333333333333333))
    x = (x + (x >> np.uint64(4))) & np.uint64(0x0F0F0F0F0F0F0F0F)
    return (x * np.uint64(0x0101010101010101)) >> np.uint64(56)


@njit(cache=True, nogil=True)
def hamming_pairs(da, db, ia, jb):
    """Hamming distances ``(P,)`` (bits) between binary descriptors ``da[ia]`` and ``db[jb]`` (uint64 words):
    the pair path's distance, which :func:`window_best_two_hamming` fuses (the tests compare the two)."""
    out = np.empty(ia.shape[0])
    words = da.shape[1]
    for p in range(ia.shape[0]):
        a, b = ia[p], jb[p]
        total = np.uint64(0)
        for w in range(words):
            total += _popcount64(da[a, w] ^ db[b, w])
        out[p] = float(total)
    return out


@njit(cache=True, nogil=True)
def window_best_two_hamming(pa, pb, order_b, vb_sorted, da, db, v_tol, du_lo, du_hi):
    """:func:`window_pairs`, :func:`hamming_pairs` and :func:`best_two` both ways in one pass, without
    materialising the candidate pairs (binary descriptors, the default path).

    Returns:
        ``best (Na,)``, ``d1 (Na,)``, ``d2 (Na,)`` (bits; -1 / inf where a keypoint has no candidate),
        and ``back (Nb,)``: for each keypoint of the second image, its nearest of the first. Pairs are
        visited in the order :func:`window_pairs` lists them, so ties resolve as there.
    """
    na, nb = pa.shape[0], pb.shape[0]
    words = da.shape[1]
    best = np.full(na, -1, np.int64)
    d1 = np.full(na, np.inf)
    d2 = np.full(na, np.inf)
    back = np.full(nb, -1, np.int64)
    b1 = np.full(nb, np.inf)
    starts = np.searchsorted(vb_sorted, pa[:, 1] - v_tol, side="left")
    stops = np.searchsorted(vb_sorted, pa[:, 1] + v_tol, side="right")
    # the second image's columns and descriptors in the scanning order: read one after another
    ub_sorted = np.empty(nb)
    db_sorted = np.empty((nb, words), np.uint64)
    for s in range(nb):
        ub_sorted[s] = pb[order_b[s], 0]
        for w in range(words):
            db_sorted[s, w] = db[order_b[s], w]
    for i in range(na):
        ua = pa[i, 0]
        for s in range(starts[i], stops[i]):
            du = ua - ub_sorted[s]
            if du_lo <= du <= du_hi:
                j = order_b[s]
                total = np.uint64(0)
                for w in range(words):
                    total += _popcount64(da[i, w] ^ db_sorted[s, w])
                d = float(total)
                if d < d1[i]:
                    d2[i] = d1[i]
                    d1[i] = d
                    best[i] = j
                elif d < d2[i]:
                    d2[i] = d
                if d < b1[j]:
                    b1[j] = d
                    back[j] = i
    return best, d1, d2, back


@njit(cache=True, nogil=True)
def l2_pairs(da, db, ia, jb):
    """Euclidean distances ``(P,)`` between float descriptors ``da[ia]`` and ``db[jb]``."""
    out = np.empty(ia.shape[0])
    dims = da.shape[1]
    for p in range(ia.shape[0]):
        a, b = ia[p], jb[p]
        total = 0.0
        for k in range(dims):
            diff = float(da[a, k]) - float(db[b, k])
            total += diff * diff
        out[p] = np.sqrt(total)
    return out


@njit(cache=True, nogil=True)
def best_two(rows, cols, dist, n_rows):
    """Per row ``r < n_rows``: the column of the nearest pair, its distance and the second nearest's.

    Returns:
        ``best (n_rows,)`` int64 (-1 where a row has no pair), ``d1``, ``d2`` ``(n_rows,)``
        (inf where missing). Ties keep the first pair in input order.
    """
    best = np.full(n_rows, -1, np.int64)
    d1 = np.full(n_rows, np.inf)
    d2 = np.full(n_rows, np.inf)
    for p in range(rows.shape[0]):
        r, d = rows[p], dist[p]
        if d < d1[r]:
            d2[r] = d1[r]
            d1[r] = d
            best[r] = cols[p]
        elif d < d2[r]:
            d2[r] = d
    return best, d1, d2


@njit(cache=True, nogil=True, inline="always")
def _sad(img_a, xa, ya, img_b, xb, yb, radius):
    total = 0.0
    for dy in range(-radius, radius + 1):
        for dx in range(-radius, radius + 1):
            total += abs(float(img_a[ya + dy, xa + dx]) - float(img_b[yb + dy, xb + dx]))
    return total


@njit(cache=True, nogil=True, inline="always")
def _vertex(c_minus, c0, c_plus):
    # Offset of the parabola's vertex through three equally spaced costs, in (-0.5, 0.5) at a minimum.
    denom = c_minus - 2.0 * c0 + c_plus
    if denom <= 0.0:
        return 0.0
    return 0.5 * (c_minus - c_plus) / denom


@njit(cache=True, nogil=True)
def refine_disparity(left, right, u, v, disparity, radius, search):
    """Subpixel disparities by a 1-D SAD search along the row.

    The left patch is centred on the integer pixel nearest ``(u, v)``; the right patch is tried at
    integer disparities ``round(d) - search .. round(d) + search`` and a parabola is fitted through
    the lowest cost and its neighbours.

    Returns:
        ``(M,)`` refined disparities (px); NaN where a patch leaves the image or the lowest cost lies
        on the search window's edge (the patches disagree with the descriptor match).
    """
    h, w = left.shape
    m = u.shape[0]
    out = np.full(m, np.nan)
    costs = np.empty(2 * search + 1)
    for i in range(m):
        x = int(np.floor(u[i] + 0.5))
        y = int(np.floor(v[i] + 0.5))
        d0 = int(np.floor(disparity[i] + 0.5))
        if y - radius < 0 or y + radius >= h or x - radius < 0 or x + radius >= w:
            continue
        xr_low = x - d0 - search - radius
        xr_high = x - d0 + search + radius
        if xr_low < 0 or xr_high >= w:
            continue
        best_s = 0
        lowest = np.inf
        for s in range(-search, search + 1):
            c = _sad(left, x, y, right, x - d0 - s, y, radius)
            costs[s + search] = c
            if c < lowest:
                lowest = c
                best_s = s
        if best_s == -search or best_s == search:
            continue
        k = best_s + search
        # a disparity is a property of the neighbourhood: the same for u as for the patch centre x
        out[i] = d0 + best_s + _vertex(costs[k - 1], costs[k], costs[k + 1])
    return out


@njit(cache=True, nogil=True)
def refine_shift(prev, curr, up, vp, uc, vc, radius, search):
    """Subpixel positions in ``curr`` of the ``prev`` pixels ``(up, vp)`` near ``(uc, vc)``, by a 2-D
    SAD search of ``(2 search + 1)^2`` integer shifts and a parabola along each axis.

    Returns:
        ``(M, 2)`` refined ``(u, v)`` in ``curr`` (px); NaN rows where a patch leaves the image or
        the lowest cost lies on the window's edge.
    """
    h, w = prev.shape
    m = up.shape[0]
    out = np.full((m, 2), np.nan)
    side = 2 * search + 1
    costs = np.empty((side, side))
    for i in range(m):
        xp = int(np.floor(up[i] + 0.5))
        yp = int(np.floor(vp[i] + 0.5))
        xc = int(np.floor(uc[i] + 0.5))
        yc = int(np.floor(vc[i] + 0.5))
        if yp - radius < 0 or yp + radius >= h or xp - radius < 0 or xp + radius >= w:
            continue
        if yc - radius - search < 0 or yc + radius + search >= h or xc - radius - search < 0 or xc + radius + search >= w:
            continue
        bx = 0
        by = 0
        lowest = np.inf
        for sy in range(-search, search + 1):
            for sx in range(-search, search + 1):
                c = _sad(prev, xp, yp, curr, xc + sx, yc + sy, radius)
                costs[sy + search, sx + search] = c
                if c < lowest:
                    lowest = c
                    bx = sx
                    by = sy
        if abs(bx) == search or abs(by) == search:
            continue
        kx = bx + search
        ky = by + search
        dx = _vertex(costs[ky, kx - 1], costs[ky, kx], costs[ky, kx + 1])
        dy = _vertex(costs[ky - 1, kx], costs[ky, kx], costs[ky + 1, kx])
        out[i, 0] = xc + bx + dx + (up[i] - xp)
        out[i, 1] = yc + by + dy + (vp[i] - yp)
    return out


@njit(cache=True, nogil=True)
def bucket_mask(cell, response, n_cells, quota, count):
    """Bucketing's choice (:func:`stereovo.frontend.detection.bucket`) in one pass: keypoints are
    visited strongest first (ties in index order); each takes a place while its cell has fewer than
    ``quota``; then, if more than ``count`` were taken, only the first ``count`` taken stay, and if
    fewer, the strongest of the rest fill up to ``count``.

    Returns:
        ``(N,)`` bool, the chosen keypoints.
    """
    n = cell.shape[0]
    order = np.argsort(-response, kind="mergesort")
    taken = np.zeros(n_cells, np.int64)
    chosen = np.zeros(n, np.bool_)
    total = 0
    for o in order:
        c = cell[o]
        if taken[c] < quota:
            taken[c] += 1
            chosen[o] = True
            total += 1
    if total > count:
        kept = 0
        for o in order:
            if chosen[o]:
                if kept < count:
                    kept += 1
                else:
                    chosen[o] = False
    elif total < count:
        for o in order:
            if total == count:
                break
            if not chosen[o]:
                chosen[o] = True
                total += 1
    return chosen
