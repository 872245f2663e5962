"""The front end's compiled kernels (stereovo/frontend/kernels.py): Hamming distances and the fused window."""

from __future__ import annotations

import numpy as np

from stereovo.frontend import kernels


def test_hamming_kernel_counts_bits_and_best_two_picks_the_nearest():
    rng = np.random.default_rng(3)
    a = rng.integers(0, 256, (20, 32), dtype=np.uint8)
    b = rng.integers(0, 256, (30, 32), dtype=np.uint8)
    ia, jb = np.repeat(np.arange(20), 30), np.tile(np.arange(30), 20)
    got = kernels.hamming_pairs(a.view(np.uint64), b.view(np.uint64), ia, jb)
    want = np.unpackbits(a[ia] ^ b[jb], axis=1).sum(axis=1)
    assert np.array_equal(got, want)
    best, d1, d2 = kernels.best_two(ia, jb, got, 20)
    table = want.reshape(20, 30)
    assert np.array_equal(d1, table.min(axis=1))
    assert np.array_equal(d2, np.sort(table, axis=1)[:, 1])
    assert np.array_equal(table[np.arange(20), best], d1)


def test_the_fused_window_kernel_equals_the_pair_path():
    rng = np.random.default_rng(5)
    pa, pb = rng.uniform(0, 100, (300, 2)), rng.uniform(0, 100, (280, 2))
    da = rng.integers(0, 2**63, (300, 4), dtype=np.int64).astype(np.uint64)
    db = da[rng.integers(0, 300, 280)] ^ (rng.random((280, 4)) < 0.05).astype(np.uint64)  # near copies: ties
    order = np.argsort(pb[:, 1], kind="stable")
    vb = np.ascontiguousarray(pb[order, 1])
    ia, jb = kernels.window_pairs(pa, pb, order, vb, 6.0, -10.0, 25.0)
    dist = kernels.hamming_pairs(da, db, ia, jb)
    best, d1, d2 = kernels.best_two(ia, jb, dist, 300)
    back, _, _ = kernels.best_two(jb, ia, dist, 280)
    fused = kernels.window_best_two_hamming(pa, pb, order, vb, da, db, 6.0, -10.0, 25.0)
    for want, got in zip((best, d1, d2, back), fused):
        assert np.array_equal(want, got)
    assert ia.size > 300 and np.all(np.abs(pa[ia, 1] - pb[jb, 1]) <= 6) and np.all((pa[ia, 0] - pb[jb, 0]) <= 25)


def _bucket_by_sorting(xy, response, shape, rows, cols, count):
    """Bucketing written with sorts (the front end's first version): the specification the compiled pass must equal."""
    n = xy.shape[0]
    if n <= count:
        return np.arange(n)
    h, w = shape
    cell = (np.minimum((xy[:, 1] * rows / h).astype(np.int64), rows - 1) * cols
            + np.minimum((xy[:, 0] * cols / w).astype(np.int64), cols - 1))
    order = np.lexsort((-response, cell))
    sorted_cells = cell[order]
    first = np.searchsorted(sorted_cells, sorted_cells, side="left")
    rank = np.empty(n, np.int64)
    rank[order] = np.arange(n) - first
    chosen = rank < -(-count // (rows * cols))
    if chosen.sum() > count:
        idx = np.flatnonzero(chosen)
        chosen[:] = False
        chosen[idx[np.argsort(-response[idx], kind="stable")[:count]]] = True
    elif chosen.sum() < count:
        rest = np.flatnonzero(~chosen)
        chosen[rest[np.argsort(-response[rest], kind="stable")[: count - int(chosen.sum())]]] = True
    return np.flatnonzero(chosen)


def test_compiled_bucketing_equals_bucketing_by_sorting():
    from stereovo.frontend.detection import bucket

    rng = np.random.default_rng(8)
    shape = (376, 1241)
    for trial in range(40):
        n = int(rng.integers(50, 3000))
        # clustered positions leave some cells short and others over full; rounded responses tie
        centres = rng.uniform((0, 0), (1241, 376), (3, 2))
        xy = np.where(rng.random((n, 1)) < 0.5, rng.uniform((0, 0), (1241, 376), (n, 2)),
                      np.clip(centres[rng.integers(0, 3, n)] + rng.normal(0, 40, (n, 2)), 0, (1240.9, 375.9)))
        response = np.round(rng.exponential(1.0, n), 1 if trial % 2 else 6)
        rows, cols = int(rng.integers(1, 6)), int(rng.integers(1, 14))
        count = int(rng.integers(10, n + 50))
        got = bucket(xy, response, shape, rows, cols, count)
        assert np.array_equal(got, _bucket_by_sorting(xy, response, shape, rows, cols, count)), trial
        assert got.size == min(n, count)


def test_a_square_window_scanned_along_either_axis_finds_the_same_nearest_two():
    # the temporal match scans its square window along the columns (the image's long axis)
    rng = np.random.default_rng(9)
    pa, pb = rng.uniform((0, 0), (1241, 376), (400, 2)), rng.uniform((0, 0), (1241, 376), (420, 2))
    da = rng.integers(0, 2**63, (400, 4), dtype=np.int64).astype(np.uint64)
    db = rng.integers(0, 2**63, (420, 4), dtype=np.int64).astype(np.uint64)

    def window(a, b):
        order = np.argsort(b[:, 1], kind="stable")
        return kernels.window_best_two_hamming(a, b, order, np.ascontiguousarray(b[order, 1]), da, db,
                                               150.0, -150.0, 150.0)

    rows = window(pa, pb)
    cols = window(np.ascontiguousarray(pa[:, ::-1]), np.ascontiguousarray(pb[:, ::-1]))
    assert np.array_equal(rows[1], cols[1]) and np.array_equal(rows[2], cols[2])  # nearest two distances
    unique = rows[1] < rows[2]  # a strictly nearest candidate is found whichever the order
    assert unique.mean() > 0.5 and np.array_equal(rows[0][unique], cols[0][unique])
