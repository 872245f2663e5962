"""Matplotlib figures for odometry runs, rendered off-screen with the Agg canvas.

Figures are built from ``matplotlib.figure.Figure`` directly rather than
``pyplot``: no global backend switch, no display, no figure-manager leaks in
long benchmark loops.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from stereovo.metrics import SUCCESS_ROT_DEG, SUCCESS_TRANS_M, SUCCESS_TRANS_REL
from stereovo.reporting import ERROR_FLOOR

if TYPE_CHECKING:
    from matplotlib.axes import Axes

    from stereovo.odometry import OdometryResult

def plot_trajectories(ax: "Axes", est: np.ndarray, true: np.ndarray | None, label: str = "estimate") -> None:
    """Top-down view (x right, z forward; metres) of ``(F, 4, 4)`` camera-to-world poses; ``true``
    None (a recording without ground truth) draws the estimate alone, solid."""
    est = np.asarray(est, dtype=float)
    start = est if true is None else np.asarray(true, dtype=float)
    if true is not None:
        ax.plot(start[:, 0, 3], start[:, 2, 3], color="black", lw=1.5, label="ground truth")
    ax.plot(est[:, 0, 3], est[:, 2, 3], color="tab:blue", lw=1.2, ls="-" if true is None else "--", label=label)
    ax.plot(start[0, 0, 3], start[0, 2, 3], "o", color="tab:green", ms=6, label="start")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("z [m]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize="small")


def plot_odometry(result: "OdometryResult", path: str | os.PathLike, title: str | None = None) -> Path:
    """Save a PNG: top-down trajectories plus per-frame rotation and translation errors.

    Failed frames (constant-velocity fallback) are marked with red crosses;
    dashed lines show the success thresholds. Returns the written path.
    """
    fig = Figure(figsize=(13, 6), layout="constrained")
    FigureCanvasAgg(fig)
    grid = fig.add_gridspec(2, 2, width_ratios=[1.1, 1.0])
    ax_traj = fig.add_subplot(grid[:, 0])
    ax_rot = fig.add_subplot(grid[0, 1])
    ax_trans = fig.add_subplot(grid[1, 1], sharex=ax_rot)

    plot_trajectories(ax_traj, result.poses, result.true_poses, label=result.method)
    traj = result.trajectory
    ax_traj.set_title(f"ATE {traj.ate_aligned_m:.3g} m (aligned), {traj.ate_raw_m:.3g} m (raw)", fontsize="medium")

    k = np.asarray(result.frame_indices) if len(result.frame_indices) else np.arange(1, result.n_frames + 1)
    failed = np.asarray(result.fallback, dtype=bool)
    rot = np.maximum(result.column("rot_err_deg"), ERROR_FLOOR)
    trans = np.maximum(result.column("trans_err_m"), ERROR_FLOOR)
    trans_bound = np.maximum(SUCCESS_TRANS_M, SUCCESS_TRANS_REL * result.column("t_true_norm_m"))
    _error_panel(ax_rot, k, rot, failed, "rotation error [deg]")
    ax_rot.axhline(SUCCESS_ROT_DEG, color="tab:red", ls="--", lw=0.8, label="success bound")
    ax_rot.legend(loc="best", fontsize="small")
    _error_panel(ax_trans, k, trans, failed, "translation error [m]")
    ax_trans.plot(k, trans_bound, color="tab:red", ls="--", lw=0.8)
    ax_trans.set_xlabel("frame")

    s = result.summary()
    fig.suptitle(
        title
        or f"{result.method}: success {100 * s['success_rate']:.1f} %, {result.n_failed} failed of {result.n_frames} frames"
    )
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    return out


def _error_panel(ax: "Axes", k: np.ndarray, err: np.ndarray, failed: np.ndarray, ylabel: str) -> None:
    ax.semilogy(k, err, color="tab:blue", lw=0.9, marker=".", ms=3)
    if np.any(failed):
        ax.semilogy(k[failed], err[failed], "x", color="tab:red", ms=6, label="failed (fallback)")
    ax.set_ylabel(ylabel)
    ax.grid(True, which="both", alpha=0.3)
