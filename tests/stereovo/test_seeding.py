"""stereovo.seeding: the compiled seeded generators are numpy's SeedSequence generators (the
simulator's use of them is tested beside it: tests/stereovo/simulation/test_fast_paths.py and
test_sequence.py)."""

from __future__ import annotations

import numpy as np
import pytest


@pytest.mark.parametrize(
    "entropy",
    [0, 7, 2**32, 2**100 + 5, 2**127 + 3, np.int64(12345), [3, 2**40, 0], [2**62 + 5, 2**40, 2**33 + 7, 2**63 - 1]],
)
@pytest.mark.parametrize("pool_size", [4, 8])
def test_seeded_generators_are_numpys_seed_sequence_generators(entropy, pool_size):
    """The compiled hash must give numpy's own PCG64 states, for every entropy and spawn key shape."""
    from stereovo.seeding import seeded_generators

    keys = [(), (0,), (5,), (2**40 + 1, 7), (1, 2, 3, 4, 5), (0x9E3779B9, 2**64 + 9, 0)]
    ours = seeded_generators(entropy, keys, pool_size)
    reference = [np.random.default_rng(np.random.SeedSequence(entropy, spawn_key=k, pool_size=pool_size)) for k in keys]
    for a, b in zip(ours, reference):
        assert a.bit_generator.state == b.bit_generator.state
        np.testing.assert_array_equal(a.random(4), b.random(4))


def test_seeded_generators_leave_other_entropy_to_numpy():
    from stereovo.seeding import seeded_generators

    words = np.array([1, 2, 3], dtype=np.uint32)  # an array entropy: numpy's SeedSequence path
    (ours,) = seeded_generators(words, [(4,)])
    assert ours.bit_generator.state == np.random.default_rng(np.random.SeedSequence(words, spawn_key=(4,))).bit_generator.state
    with pytest.raises(ValueError, match="non-negative"):
        seeded_generators(-1, [(0,)])  # numpy's own error for negative entropy
    assert seeded_generators(5, []) == []


def test_seed_words_rows_are_the_generators_of_seeded_generators():
    from stereovo.seeding import generator_from_seed_words, seed_words, seeded_generators

    keys = [(0, 5), (3,), (), (2**40, 1, 2)]
    rows = seed_words(2**70 + 3, keys)
    assert rows.shape == (4, 4) and rows.dtype == np.uint64
    assert [generator_from_seed_words(r).bit_generator.state for r in rows] == \
        [g.bit_generator.state for g in seeded_generators(2**70 + 3, keys)]
    assert seed_words(-1, keys) is None and seed_words(5, [(-1,)]) is None and seed_words(5, [(1,)], 2) is None
    assert seed_words(5, []).shape == (0, 4)
