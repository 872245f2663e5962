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
