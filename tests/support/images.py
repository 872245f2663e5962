"""Helpers of the image tests: a rendered sequence (or a loud skip naming what is missing), a
small folder in KITTI's layout written from rendered images, and one of noise or blank images."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest


def rendered(**kwargs):
    """A :class:`RenderedSequence`, or a skip whose reason says what the platform lacks."""
    pytest.importorskip("cv2", reason="the image front end needs OpenCV: pip install 'vo-gym[images]'")
    pytest.importorskip("moderngl", reason="rendered sequences need moderngl: pip install 'vo-gym[render]'")
    from stereovo.sequences.rendering import RenderingUnavailable
    from stereovo.sequences.rendered import RenderedSequence

    try:
        return RenderedSequence(**kwargs)
    except RenderingUnavailable as err:  # pragma: no cover - only on a platform without EGL
        pytest.skip(f"NO HEADLESS OPENGL ON THIS MACHINE, rendered tests skipped: {err}")


def write_kitti(root: Path, sequence, name: str = "00", with_poses: bool = True) -> Path:
    """Write ``sequence``'s image pairs, its rig and (optionally) poses in KITTI's layout under ``root``."""
    import cv2

    folder = root / "sequences" / name
    for side in ("image_0", "image_1"):
        (folder / side).mkdir(parents=True, exist_ok=True)
    for k in range(sequence.n_images()):
        left, right = sequence.images(k)
        cv2.imwrite(str(folder / "image_0" / f"{k:06d}.png"), left)
        cv2.imwrite(str(folder / "image_1" / f"{k:06d}.png"), right)
    cam = sequence.camera
    K = f"{cam.fx:.12e} 0 {cam.cx:.12e}"
    lines = []
    for key, tx in (("P0", 0.0), ("P1", -cam.fx * cam.baseline), ("P2", 0.0), ("P3", 0.0)):
        lines.append(f"{key}: {K} {tx:.12e} 0 {cam.fy:.12e} {cam.cy:.12e} 0 0 0 1 0")
    (folder / "calib.txt").write_text("\n".join(lines) + "\n")
    (folder / "times.txt").write_text("".join(f"{0.1 * k:.6e}\n" for k in range(sequence.n_images())))
    if with_poses:
        (root / "poses").mkdir(exist_ok=True)
        rows = [" ".join(f"{x:.12e}" for x in pose[:3].ravel()) for pose in np.asarray(sequence.true_poses)]
        (root / "poses" / f"{name}.txt").write_text("\n".join(rows) + "\n")
    return folder


def write_image_folder(folder: Path, n: int = 3, width: int = 128, height: int = 96, blank: bool = False,
                       poses: bool = False) -> Path:
    """Write one sequence's folder in KITTI's layout without rendering: ``n`` image pairs of grey noise
    (of zeros when ``blank``: no features) of ``width`` x ``height`` px as ``image_0/00000K.png`` and
    ``image_1/00000K.png``, ``calib.txt`` (fx 300 px, baseline 0.5 m, the principal point at the centre)
    and, with ``poses``, ``poses.txt`` (0.1 m forward per image)."""
    import cv2

    rng = np.random.default_rng(5)
    for side in ("image_0", "image_1"):
        (folder / side).mkdir(parents=True, exist_ok=True)
        for k in range(n):
            image = np.zeros((height, width), np.uint8) if blank else rng.integers(0, 256, (height, width), np.uint8)
            assert cv2.imwrite(str(folder / side / f"{k:06d}.png"), image)
    cx, cy = width / 2, height / 2
    (folder / "calib.txt").write_text(f"P0: 300 0 {cx} 0 0 300 {cy} 0 0 0 1 0\n"
                                      f"P1: 300 0 {cx} -150 0 300 {cy} 0 0 0 1 0\n")
    if poses:
        (folder / "poses.txt").write_text("".join(f"1 0 0 0 0 1 0 0 0 0 1 {0.1 * k}\n" for k in range(n)))
    return folder
