"""Trajectory and per-frame table export: TUM, KITTI and CSV.

Poses are ``(F, 4, 4)`` camera-to-world matrices (metres). Floats are written
with ``repr`` (shortest string that round-trips exactly), so a write/read
cycle is lossless. Fields are separated by single spaces: evo's TUM reader
rejects doubled ones.
"""

from __future__ import annotations

import csv
import os
from pathlib import Path
from typing import Any, Iterable, Sequence

import numpy as np

from stereovo.geometry import quaternion_from_rotation

PathLike = str | os.PathLike


def _fmt(x: Any) -> str:
    return repr(float(x))


def _check_poses(poses: np.ndarray) -> np.ndarray:
    poses = np.asarray(poses, dtype=float)
    if poses.ndim != 3 or poses.shape[1:] != (4, 4):
        raise ValueError(f"poses must have shape (F, 4, 4), got {poses.shape}")
    return poses


def _open_for_write(path: PathLike):
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    return path.open("w", newline="")


def write_tum(path: PathLike, poses: np.ndarray, timestamps: Sequence[float] | None = None) -> None:
    """Write ``t tx ty tz qx qy qz qw`` lines (TUM RGB-D format).

    Args:
        path: output file; parent folders are created.
        poses: ``(F, 4, 4)`` camera-to-world poses.
        timestamps: ``(F,)`` seconds; defaults to the frame index.
    """
    poses = _check_poses(poses)
    if timestamps is None:
        ts = np.arange(len(poses), dtype=float)
    else:
        ts = np.asarray(timestamps, dtype=float)
        if ts.shape != (len(poses),):
            raise ValueError(f"timestamps must have shape ({len(poses)},), got {ts.shape}")
    q = quaternion_from_rotation(poses[:, :3, :3])
    rows = np.column_stack([ts, poses[:, :3, 3], q])
    with _open_for_write(path) as fh:
        fh.writelines(" ".join(map(_fmt, row)) + "\n" for row in rows)


def write_kitti(path: PathLike, poses: np.ndarray) -> None:
    """Write the 12 row-major entries of each 3x4 camera-to-world pose, one pose per line."""
    poses = _check_poses(poses)
    rows = poses[:, :3, :].reshape(len(poses), 12)
    with _open_for_write(path) as fh:
        fh.writelines(" ".join(map(_fmt, row)) + "\n" for row in rows)


def _numeric_rows(path: PathLike, n_fields: int) -> np.ndarray:
    """Rows of whitespace- (or comma-) separated numbers, skipping blanks and ``#`` comments."""
    rows = []
    with Path(path).open() as fh:
        for lineno, line in enumerate(fh, start=1):
            line = line.strip()
            if not line or line.startswith("#"):
                continue
            fields = line.replace(",", " ").split()
            if len(fields) != n_fields:
                raise ValueError(f"{path}:{lineno}: expected {n_fields} numbers, got {len(fields)}")
            rows.append([float(f) for f in fields])
    return np.asarray(rows, dtype=float).reshape(-1, n_fields)


def _rotation_from_quaternion(q: np.ndarray) -> np.ndarray:
    """Rotations ``(F, 3, 3)`` from quaternions ``(F, 4)`` ordered ``(qx, qy, qz, qw)``."""
    norm = np.linalg.norm(q, axis=1, keepdims=True)
    if np.any(~(norm > 0)):
        raise ValueError("zero or non-finite quaternion in trajectory file")
    x, y, z, w = (q / norm).T
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], axis=-1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], axis=-1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], axis=-1),
        ],
        axis=-2,
    )


def read_tum(path: PathLike) -> tuple[np.ndarray, np.ndarray]:
    """Read a TUM file: ``(poses (F, 4, 4), timestamps (F,))``."""
    rows = _numeric_rows(path, 8)
    poses = np.tile(np.eye(4), (len(rows), 1, 1))
    poses[:, :3, :3] = _rotation_from_quaternion(rows[:, 4:8])
    poses[:, :3, 3] = rows[:, 1:4]
    return poses, rows[:, 0].copy()


def read_kitti(path: PathLike) -> np.ndarray:
    """Read a KITTI pose file: ``(F, 4, 4)`` camera-to-world poses."""
    rows = _numeric_rows(path, 12)
    poses = np.tile(np.eye(4), (len(rows), 1, 1))
    poses[:, :3, :] = rows.reshape(-1, 3, 4)
    return poses


def _csv_value(v: Any) -> Any:
    # Floats at full precision; numpy scalars unwrapped so bools print as True/False.
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, float):
        return repr(v)
    return v


def write_frame_csv(path: PathLike, rows: Iterable[dict[str, Any]]) -> None:
    """Write per-frame dicts as CSV; columns are the union of keys in first-seen order."""
    rows = list(rows)
    columns: dict[str, None] = {}
    for row in rows:
        columns.update(dict.fromkeys(row))
    with _open_for_write(path) as fh:
        writer = csv.DictWriter(fh, fieldnames=list(columns), restval="")
        writer.writeheader()
        for row in rows:
            writer.writerow({k: _csv_value(v) for k, v in row.items()})
