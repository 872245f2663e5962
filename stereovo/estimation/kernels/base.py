"""What every compiled kernel shares: the numba options and the depth below which nothing projects.

All kernels compile with ``cache=True`` (the machine code is kept on disk beside each
source file, so a second process loads it instead of compiling), ``nogil=True`` and
numpy's error model (a division by zero gives inf or nan, as in numpy, instead of raising).
"""

from __future__ import annotations

from numba import njit

MIN_DEPTH = 1e-3  # a transformed point this close to the camera plane cannot be projected
BEHIND_CAMERA_RESIDUAL = 1e3  # its residual rows are set to this and its Jacobian zeroed

jit = njit(cache=True, nogil=True, error_model="numpy")
# Helpers that take arrays and run once per point or per hypothesis are inlined into their callers:
# a compiled call passes each array as a struct and reference-counts it on entry and exit, which
# cost more than the arithmetic of a point's residual (docs/performance.md, "Measurements behind the code").
inline_jit = njit(cache=True, nogil=True, error_model="numpy", inline="always")
