"""Generators seeded exactly as ``np.random.default_rng(np.random.SeedSequence(...))`` seeds them, faster.

numpy hashes a SeedSequence's entropy and builds the PCG64 state in Python-level loops:
about 10 microseconds a generator, and the simulator makes six a frame (the frame's own
and its five streams). :func:`seeded_generators` runs the same hash (numpy's
``SeedSequence.mix_entropy`` and ``generate_state``, integer arithmetic mod 2**32) compiled,
for a whole batch of spawn keys at once, and hands PCG64 the resulting seed words; the
generators' states are bit for bit numpy's (``tests/test_simulation.py`` compares them).
Inputs outside the fast path (entropy that is not a non-negative int or a list of them)
go through numpy's SeedSequence itself.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numba import njit
from numpy.random.bit_generator import ISeedSequence

__all__ = ["generator_from_seed_words", "seed_words", "seeded_generators", "spawned_generators"]

_MASK32 = np.uint64(0xFFFFFFFF)
_INIT_A = np.uint64(0x43B0D7E5)
_MULT_A = np.uint64(0x931E8875)
_INIT_B = np.uint64(0x8B51F9DD)
_MULT_B = np.uint64(0x58F38DED)
_MIX_MULT_L = np.uint64(0xCA01F9DD)
_MIX_MULT_R = np.uint64(0x4973F715)
_XSHIFT = np.uint64(16)


@njit(cache=True, nogil=True, inline="always")
def _hashmix(value, hash_const, multiplier):
    """numpy's ``hashmix`` (``multiplier`` MULT_A) and ``generate_state`` step (MULT_B):
    ``(hashed value, next hash constant)``."""
    value ^= hash_const
    hash_const = (hash_const * multiplier) & _MASK32
    value = (value * hash_const) & _MASK32
    return value ^ (value >> _XSHIFT), hash_const


@njit(cache=True, nogil=True, inline="always")
def _mix(x, y):
    """numpy's ``mix`` of two 32-bit words."""
    result = (_MIX_MULT_L * x - _MIX_MULT_R * y) & _MASK32
    return result ^ (result >> _XSHIFT)


@njit(cache=True, nogil=True)
def _pcg64_seed_words(entropy, spawn_words, spawn_lengths, pool_size):
    """``(S, 4)`` uint64: ``SeedSequence(entropy, spawn_key=key_s, pool_size).generate_state(4, uint64)``.

    ``entropy`` ``(E,)`` and ``spawn_words`` ``(S, L)`` are 32-bit words held in uint64 (row s
    uses its first ``spawn_lengths[s]``). Every product is of two values under 2**32, so it fits
    in 64 bits; masking afterwards is arithmetic mod 2**32, as numpy's uint32 C code.
    """
    n_streams = spawn_words.shape[0]
    out = np.empty((n_streams, 4), dtype=np.uint64)
    pool = np.empty(pool_size, dtype=np.uint64)
    for s in range(n_streams):
        n_spawn = spawn_lengths[s]
        # get_assembled_entropy: the run entropy, zero-padded to the pool when a spawn key follows
        n_run = entropy.shape[0]
        if n_spawn > 0 and n_run < pool_size:
            n_run = pool_size
        assembled = np.zeros(max(n_run + n_spawn, pool_size), dtype=np.uint64)
        assembled[: entropy.shape[0]] = entropy
        assembled[n_run:n_run + n_spawn] = spawn_words[s, :n_spawn]
        n_words = n_run + n_spawn
        # mix_entropy: the first pool_size words (zeros past the end) seed the pool, every
        # word mixes into every other pool word, then the words past the pool mix into all
        hash_const = _INIT_A
        for i in range(pool_size):
            pool[i], hash_const = _hashmix(assembled[i], hash_const, _MULT_A)
        for i_src in range(pool_size):
            for i_dst in range(pool_size):
                if i_src != i_dst:
                    value, hash_const = _hashmix(pool[i_src], hash_const, _MULT_A)
                    pool[i_dst] = _mix(pool[i_dst], value)
        for i_src in range(pool_size, n_words):
            for i_dst in range(pool_size):
                value, hash_const = _hashmix(assembled[i_src], hash_const, _MULT_A)
                pool[i_dst] = _mix(pool[i_dst], value)
        # generate_state: 8 uint32 words (the pool cycled, hashed with the second constants),
        # read as 4 little-endian uint64
        hash_const = _INIT_B
        for j in range(4):
            low, hash_const = _hashmix(pool[(2 * j) % pool_size], hash_const, _MULT_B)
            high, hash_const = _hashmix(pool[(2 * j + 1) % pool_size], hash_const, _MULT_B)
            out[s, j] = low | (high << np.uint64(32))
    return out


class _SeedWords(ISeedSequence):
    """Hands PCG64 seed words computed already (PCG64 asks its seed for ``generate_state(4, uint64)``)."""

    __slots__ = ("words",)

    def __init__(self, words: np.ndarray) -> None:
        self.words = words

    def generate_state(self, n_words: int, dtype=np.uint32) -> np.ndarray:
        if n_words != 4 or np.dtype(dtype) != np.uint64:
            raise ValueError("precomputed seed words serve PCG64 only (4 uint64 words)")
        return self.words


def _as_words(ints: Sequence[int]) -> list[int] | None:
    """numpy's little-endian 32-bit words of non-negative ints (one zero word for 0), concatenated;
    None for anything else."""
    words: list[int] = []
    for value in ints:
        if type(value) is not int:
            if not isinstance(value, np.integer):
                return None
            value = int(value)
        if value < 0:
            return None
        words.append(value & 0xFFFFFFFF)
        value >>= 32
        while value:
            words.append(value & 0xFFFFFFFF)
            value >>= 32
    return words


def seeded_generators(
    entropy: int | Sequence[int], spawn_keys: Sequence[tuple[int, ...]], pool_size: int = 4
) -> list[np.random.Generator]:
    """``[np.random.default_rng(np.random.SeedSequence(entropy, spawn_key=k, pool_size=pool_size))
    for k in spawn_keys]``, bit for bit, without numpy's per-generator hashing cost.

    Args:
        entropy: a non-negative int or a sequence of them (other entropy goes through numpy).
        spawn_keys: one tuple of non-negative ints per generator.
        pool_size: the SeedSequence pool size in 32-bit words (numpy's default 4).
    """
    if not spawn_keys:
        return []
    seeds = seed_words(entropy, spawn_keys, pool_size)
    if seeds is None:
        return [np.random.default_rng(np.random.SeedSequence(entropy, spawn_key=tuple(key), pool_size=pool_size))
                for key in spawn_keys]
    return [generator_from_seed_words(words) for words in seeds]


def seed_words(
    entropy: int | Sequence[int], spawn_keys: Sequence[tuple[int, ...]], pool_size: int = 4
) -> np.ndarray | None:
    """``(S, 4)`` uint64: the PCG64 seed words of ``SeedSequence(entropy, spawn_key=k, pool_size)`` for
    each of the S ``spawn_keys``, computed at once (e.g. a sequence's frames ahead, then one
    :func:`generator_from_seed_words` a frame); None for entropy or keys outside the fast path
    (:func:`seeded_generators` then asks numpy)."""
    if not spawn_keys:
        return np.zeros((0, 4), dtype=np.uint64)
    run = _as_words((entropy,) if isinstance(entropy, (int, np.integer)) else entropy) \
        if isinstance(entropy, (int, np.integer, list, tuple)) else None
    keys = [_as_words(key) for key in spawn_keys]
    if not run or None in keys or type(pool_size) is not int or pool_size < 4:
        return None
    width = max(1, max(len(key) for key in keys))
    return _pcg64_seed_words(
        np.array(run, dtype=np.uint64),
        np.array([key + [0] * (width - len(key)) for key in keys], dtype=np.uint64),
        np.array([len(key) for key in keys], dtype=np.int64),
        pool_size,
    )


def generator_from_seed_words(words: np.ndarray) -> np.random.Generator:
    """The PCG64 generator of one row of :func:`seed_words` (numpy's ``default_rng`` of that seed sequence)."""
    return np.random.Generator(np.random.PCG64(_SeedWords(words)))


@njit(cache=True, nogil=True)
def _spawned_seed_words(entropy, n_children, pool_size):
    """``(n_children, 4)`` uint64 seed words of ``SeedSequence(list(entropy)).spawn(n_children)``,
    ``entropy`` ``(E,)`` int64; ``(0, 4)`` when an entry is negative (numpy's error is the caller's).

    The entries' 32-bit words as :func:`_as_words` splits them (the low word, then the high one
    when it is not zero), and the children's spawn keys ``(0,)``, ``(1,)``, ...
    """
    words = np.empty(2 * entropy.shape[0], dtype=np.uint64)
    n_words = 0
    for value in entropy:
        if value < 0:
            return np.empty((0, 4), dtype=np.uint64)
        word = np.uint64(value)
        words[n_words] = word & _MASK32
        n_words += 1
        high = word >> np.uint64(32)
        if high != 0:
            words[n_words] = high
            n_words += 1
    spawn = np.empty((n_children, 1), dtype=np.uint64)
    for child in range(n_children):
        spawn[child, 0] = child
    return _pcg64_seed_words(words[:n_words], spawn, np.ones(n_children, dtype=np.int64), pool_size)


def spawned_generators(entropy: np.ndarray, n_children: int) -> list[np.random.Generator]:
    """``[np.random.default_rng(s) for s in np.random.SeedSequence(entropy.tolist()).spawn(n_children)]``
    for an int64 array ``entropy`` ``(E,)`` (a frame's ``rng.integers(0, 2**63, size=4)``), bit for bit.

    :func:`seeded_generators` with the spawn keys ``(0,)`` to ``(n_children - 1,)``, the words
    computed in the compiled pass: about half its cost, for the simulator's five streams a frame.
    """
    if n_children <= 0:
        return []
    if entropy.dtype == np.int64 and entropy.ndim == 1 and entropy.size:
        seeds = _spawned_seed_words(entropy, n_children, 4)
        if seeds.shape[0]:
            return [generator_from_seed_words(words) for words in seeds]
    return seeded_generators(entropy.tolist(), [(i,) for i in range(n_children)])
