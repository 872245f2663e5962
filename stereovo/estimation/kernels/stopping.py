"""The adaptive stopping bound, compiled once for the termination role and the compiled search.

:func:`adaptive_bound` is ``k = ceil(log(1 - p) / log(1 - q))`` in ``[1, max_iterations]`` with ``q``
the chance that ``sample_size`` uniform draws without replacement from ``n`` rows are all among
``count`` inliers (Schoenberger, Larsson & Pollefeys 2025: the product ``prod (I - i) / (N - i)``,
not ``w^s``). :func:`stereovo.estimation.roles.termination.required_iterations` and
:mod:`stereovo.estimation.kernels.batch_search` both call it, so the loop and the kernel stop alike.
"""

from __future__ import annotations

import math

from stereovo.estimation.kernels.base import jit


@jit
def adaptive_bound(count, n, confidence, max_iterations, sample_size):
    """The bound for ``count`` inliers (a float) of ``n`` rows at ``confidence``, clipped to
    ``[1, max_iterations]``: ``max_iterations`` where no all-inlier draw is possible, 1 where every
    draw is one."""
    q = 1.0
    for i in range(sample_size):
        q = q * max(count - i, 0.0) / max(n - i, 1)
    if q <= 0.0:
        return max_iterations
    if q >= 1.0:
        return 1
    ratio = math.log1p(-confidence) / math.log1p(-q)
    # Python's ceil is exact at any size, an int64 is not: a ratio past the cap is the cap
    return max_iterations if ratio >= max_iterations else min(max(int(math.ceil(ratio)), 1), max_iterations)
