"""stereovo: stereo camera, trajectory simulator, shared RANSAC estimator core and visual odometry."""

from stereovo.compilation import announce_compiling

# Before any kernel can compile, once for every entry point (an estimate, a simulated frame, an
# environment's reset): the first compilation of one of the package's kernels in this process then
# prints one line, and a run whose kernels all load from numba's cache prints none.
announce_compiling()

from stereovo.camera import StereoCamera  # noqa: E402
from stereovo.estimation import MotionEstimate, available_methods, estimate_motion  # noqa: E402

__all__ = ["StereoCamera", "MotionEstimate", "available_methods", "estimate_motion"]
__version__ = "0.1.0"
