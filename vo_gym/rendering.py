"""``rgb_array`` rendering of :class:`vo_gym.StereoVOEnv`, off-screen with matplotlib's Agg canvas.

Left: the estimated and true trajectories so far (top-down,
:func:`stereovo.plotting.plot_trajectories`). Right: the frame pair's matches
in the left image at k, a segment from the k-1 position, coloured by the
agent's sampling weight relative to uniform (log scale); the estimate's
inliers are ringed.
"""

from __future__ import annotations

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection
from matplotlib.colors import LogNorm
from matplotlib.figure import Figure

from stereovo.plotting import plot_trajectories

__all__ = ["render_rgb"]

_WEIGHT_RANGE = (1e-2, 1e2)  # weights relative to uniform shown on the colour scale


def render_rgb(
    est_poses: np.ndarray,
    true_poses: np.ndarray,
    frame,
    weights: np.ndarray | None = None,
    inliers: np.ndarray | None = None,
    title: str = "",
    size_px: tuple[int, int] = (1200, 420),
    dpi: int = 100,
) -> np.ndarray:
    """An ``(H, W, 3)`` uint8 image of the trajectories and one frame pair's matches.

    Args:
        est_poses, true_poses: ``(F, 4, 4)`` camera-to-world poses.
        frame: a :class:`stereovo.simulation.Frame` (only its measurements and camera are drawn).
        weights: ``(N,)`` sampling weights relative to uniform (1 = uniform); None draws grey.
        inliers: ``(N,)`` bool, the estimate's inliers, ringed; None draws none.
        title: figure title.
        size_px: ``(width, height)`` of the image.
    """
    fig = Figure(figsize=(size_px[0] / dpi, size_px[1] / dpi), dpi=dpi, layout="constrained")
    canvas = FigureCanvasAgg(fig)
    grid = fig.add_gridspec(1, 2, width_ratios=[1.0, 2.2])
    ax_traj = fig.add_subplot(grid[0, 0])
    ax_img = fig.add_subplot(grid[0, 1])

    if len(est_poses):
        plot_trajectories(ax_traj, est_poses, true_poses)
    ax_traj.set_title("trajectory (top-down)", fontsize="small")

    cam = frame.camera
    prev, curr = np.asarray(frame.prev), np.asarray(frame.curr)
    segments = np.stack([prev[:, :2], curr[:, :2]], axis=1)
    if weights is None:
        ax_img.add_collection(LineCollection(segments, colors="0.6", linewidths=0.6))
        ax_img.scatter(curr[:, 0], curr[:, 1], s=6, c="0.4")
    else:
        w = np.clip(np.asarray(weights, dtype=float), *_WEIGHT_RANGE)
        norm = LogNorm(*_WEIGHT_RANGE)
        order = np.argsort(w)  # heaviest on top
        lines = LineCollection(segments[order], cmap="viridis", norm=norm, linewidths=0.6)
        lines.set_array(w[order])
        ax_img.add_collection(lines)
        points = ax_img.scatter(curr[order, 0], curr[order, 1], s=6, c=w[order], cmap="viridis", norm=norm)
        fig.colorbar(points, ax=ax_img, label="sampling weight / uniform", shrink=0.8)
    if inliers is not None and np.any(inliers):
        ax_img.scatter(curr[inliers, 0], curr[inliers, 1], s=22, facecolors="none", edgecolors="tab:red",
                       linewidths=0.5, label="estimated inliers")
        ax_img.legend(loc="upper right", fontsize="x-small")
    ax_img.set_xlim(0, cam.width - 1)
    ax_img.set_ylim(cam.height - 1, 0)
    ax_img.set_aspect("equal")
    ax_img.set_xlabel("u [px]")
    ax_img.set_ylabel("v [px]")
    ax_img.set_title("matches at k (segments from k-1)", fontsize="small")
    if title:
        fig.suptitle(title, fontsize="medium")
    canvas.draw()
    image = np.asarray(canvas.buffer_rgba())[..., :3].copy()
    return image
