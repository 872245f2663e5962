"""Which rows of a frame pair have a resolvable depth: the disparity rule of :mod:`stereovo.estimation.problem`.

:class:`~stereovo.estimation.problem.StereoProblem` flags a row unusable where, at k-1 or at k,
the disparity ``uL - uR`` is at or below ``min_disparity_sigmas`` standard deviations of its noise
(:func:`~stereovo.estimation.problem.resolvable_depth`). Built once a frame, beside the two
triangulations; one pass here instead of the numpy expression's temporaries and the two ``all()``
reductions that follow it, which cost more than the comparisons at 500 rows.
"""

from __future__ import annotations

from stereovo.estimation.kernels.base import jit


@jit
def resolvable_rows(prev, curr, threshold, apply, usable_prev, usable_curr):
    """In place, if ``apply``: ``usable_prev &= (prev[:, 0] - prev[:, 2]) > threshold`` and the same
    for ``curr``; returns whether every entry of both masks is True afterwards.

    ``prev``, ``curr`` are ``(N, 4)`` float64 measurements (px), ``usable_prev``, ``usable_curr``
    ``(N,)`` bool, ``threshold`` the disparity bound (px) as the caller computes it. A NaN or inf
    disparity fails the comparison, as in numpy.
    """
    every = True
    for i in range(prev.shape[0]):
        if apply:
            usable_prev[i] = usable_prev[i] and (prev[i, 0] - prev[i, 2]) > threshold
            usable_curr[i] = usable_curr[i] and (curr[i, 0] - curr[i, 2]) > threshold
        every = every and usable_prev[i] and usable_curr[i]
    return every
