"""stereovo: stereo camera, trajectory simulator, shared RANSAC estimator core and visual odometry."""

from stereovo.camera import StereoCamera
from stereovo.estimation import MotionEstimate, available_methods, estimate_motion

__all__ = ["StereoCamera", "MotionEstimate", "available_methods", "estimate_motion"]
__version__ = "0.1.0"
