"""The rendered world's geometry, built along a camera trajectory from a seed.

``street`` (the ``car`` preset): a road that follows the trajectory (its height follows the
camera's, so the camera stays at ``CAMERA_HEIGHT`` above it), kerbed sidewalks, building
facades in blocks on both sides with gaps between them, and clutter (poles, bins, parked
cars). ``open`` (the ``free`` preset): textured boxes scattered around the path inside a
textured enclosure. Moving objects are boxes with their own motion (:class:`MovingObject`).

Meshes are float32 vertex rows ``(x, y, z, s, t, layer, shade)``: a world (or object) position
in metres (camera axes of frame 0: x right, y down, z forward), texture coordinates in tiles, the
texture layer (:data:`~stereovo.sequences.textures.LAYERS`) and a fixed Lambertian shade.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from stereovo.geometry import so3_exp
from stereovo.sequences.textures import LAYERS

CAMERA_HEIGHT = 1.65
"""Height of the ``car`` camera above the road (m), KITTI's."""

_LIGHT = np.array([0.4, -0.8, -0.45]) / np.linalg.norm([0.4, -0.8, -0.45])
_LAYER = {name: float(i) for i, name in enumerate(LAYERS)}
_FACADES = ("facade_brick", "facade_windows", "facade_panels", "facade_stone")
_CLUTTER = ("clutter_blobs", "clutter_checker", "clutter_stripes", "clutter_marks")
_DOWN = np.array([0.0, 1.0, 0.0])


def _quad(a, b, c, d, st, layer) -> np.ndarray:
    """Two triangles of the quad ``a b c d`` (corners in order) with texture coordinates ``st (4, 2)``."""
    corners = np.array([a, b, c, d], dtype=float)
    normal = np.cross(corners[1] - corners[0], corners[3] - corners[0])
    norm = np.linalg.norm(normal)
    shade = 0.55 + 0.45 * abs(float(normal @ _LIGHT)) / norm if norm > 0 else 1.0
    rows = np.empty((4, 7))
    rows[:, :3] = corners
    rows[:, 3:5] = st
    rows[:, 5] = layer
    rows[:, 6] = shade
    return rows[[0, 1, 2, 0, 2, 3]]


def box_mesh(size: np.ndarray, layer: float, tile: float = 2.0) -> np.ndarray:
    """A box ``size = (w, h, l)`` (m) centred at the origin, textured ``tile`` m per texture tile."""
    w, h, l = np.asarray(size, dtype=float) / 2
    c = np.array([[x, y, z] for x in (-w, w) for y in (-h, h) for z in (-l, l)])
    faces = [(0, 1, 3, 2, 2 * l, 2 * h), (4, 6, 7, 5, 2 * h, 2 * l), (0, 4, 5, 1, 2 * w, 2 * l),
             (2, 3, 7, 6, 2 * l, 2 * w), (0, 2, 6, 4, 2 * h, 2 * w), (1, 5, 7, 3, 2 * w, 2 * h)]
    quads = []
    for i0, i1, i2, i3, su, sv in faces:
        st = np.array([[0, 0], [su, 0], [su, sv], [0, sv]]) / tile
        quads.append(_quad(c[i0], c[i1], c[i2], c[i3], st, layer))
    return np.concatenate(quads)


def _placed(mesh: np.ndarray, rotation: np.ndarray, position: np.ndarray) -> np.ndarray:
    out = mesh.copy()
    out[:, :3] = mesh[:, :3] @ rotation.T + position
    return out


@dataclass(frozen=True)
class MovingObject:
    """A box moving on its own: ``mesh`` in its own frame, ``poses (F+1, 4, 4)`` object-to-world per frame."""

    mesh: np.ndarray
    poses: np.ndarray


@dataclass(frozen=True)
class Centreline:
    """The trajectory's ground track resampled every ``step`` m: positions ``(S, 3)`` (at the
    camera), horizontal unit forward and right vectors ``(S, 3)``, and arc lengths ``(S,)`` (m)."""

    points: np.ndarray
    forward: np.ndarray
    right: np.ndarray
    arc: np.ndarray

    def at(self, s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position, forward and right at arc length ``s`` (m), linearly interpolated."""
        i = int(np.clip(np.searchsorted(self.arc, s) - 1, 0, len(self.arc) - 2))
        w = float(np.clip((s - self.arc[i]) / max(self.arc[i + 1] - self.arc[i], 1e-9), 0.0, 1.0))
        p = (1 - w) * self.points[i] + w * self.points[i + 1]
        f = (1 - w) * self.forward[i] + w * self.forward[i + 1]
        f /= np.linalg.norm(f)
        return p, f, np.cross(_DOWN, f)


def centreline(poses: np.ndarray, step: float = 2.0, margin: float = 120.0) -> Centreline:
    """The ground track of camera-to-world ``poses``, extended straight by ``margin`` m at both ends
    (the camera sees ahead of its last pose and may look back)."""
    positions = poses[:, :3, 3]
    forward = poses[:, :3, 2].copy()
    forward[:, 1] = 0.0
    forward /= np.maximum(np.linalg.norm(forward, axis=1, keepdims=True), 1e-9)
    head = positions[0] - forward[0] * margin
    tail = positions[-1] + forward[-1] * margin
    track = np.vstack([head, positions, tail])
    heading = np.vstack([forward[:1], forward, forward[-1:]])
    seg = np.linalg.norm(np.diff(track, axis=0), axis=1)
    arc = np.concatenate([[0.0], np.cumsum(seg)])
    samples = np.arange(0.0, arc[-1], step)
    points = np.column_stack([np.interp(samples, arc, track[:, i]) for i in range(3)])
    fwd = np.column_stack([np.interp(samples, arc, heading[:, i]) for i in range(3)])
    # a heading smoothed over ~10 m keeps facades from folding where the camera yaws in place
    kernel = np.ones(5) / 5
    fwd = np.column_stack([np.convolve(np.pad(fwd[:, i], 2, mode="edge"), kernel, mode="valid") for i in range(3)])
    fwd[:, 1] = 0.0
    fwd /= np.maximum(np.linalg.norm(fwd, axis=1, keepdims=True), 1e-9)
    right = np.cross(_DOWN, fwd)
    return Centreline(points, fwd, right, samples - margin)


def _strip(line: Centreline, i0: int, i1: int, lateral: tuple[float, float], drop: tuple[float, float],
           layer: float, tile: tuple[float, float]) -> list[np.ndarray]:
    """Quads along the centreline between samples i0 and i1 from ``lateral[0]`` to ``lateral[1]`` m
    right of it and ``drop`` m below the camera (a horizontal strip when the drops are equal, a wall
    when the laterals are)."""
    quads = []
    for i in range(i0, i1):
        corners = []
        for j in (i, i + 1):
            p, r = line.points[j], line.right[j]
            corners.append([p + r * lateral[0] + _DOWN * drop[0], p + r * lateral[1] + _DOWN * drop[1]])
        (a, b), (d, c) = corners
        span = np.linalg.norm(np.array(b) - np.array(a)) / tile[0]
        s0, s1 = line.arc[i] / tile[1], line.arc[i + 1] / tile[1]
        quads.append(_quad(a, b, c, d, np.array([[0, s0], [span, s0], [span, s1], [0, s1]]), layer))
    return quads


def street_world(poses: np.ndarray, rng: np.random.Generator, n_moving: int) -> tuple[np.ndarray, list[MovingObject]]:
    """The ``street`` world along camera-to-world ``poses (F+1, 4, 4)``: static mesh and moving objects."""
    line = centreline(poses)
    h = CAMERA_HEIGHT
    half_road, walk = 5.0, 3.0
    n = len(line.arc) - 1
    quads = _strip(line, 0, n, (-half_road, half_road), (h, h), _LAYER["road"], (10.0, 8.0))
    for side in (-1.0, 1.0):
        edge = side * half_road
        quads += _strip(line, 0, n, (edge, edge), (h, h - 0.15), _LAYER["sidewalk"], (1.0, 2.0))  # kerb
        far = side * (half_road + walk + 3.5)  # under the facades, which stand back up to 3 m
        quads += _strip(line, 0, n, (edge, far) if side > 0 else (far, edge), (h - 0.15, h - 0.15),
                        _LAYER["sidewalk"], (3.0, 3.0))
        i = 0
        while i < n:
            length = int(rng.integers(5, 16))  # samples of 2 m
            if rng.random() < 0.85:
                offset = side * (half_road + walk + rng.uniform(0.0, 3.0))
                height = rng.uniform(6.0, 18.0)
                layer = _LAYER[_FACADES[int(rng.integers(len(_FACADES)))]]
                quads += _strip(line, i, min(i + length, n), (offset, offset), (h - 0.15, h - height), layer,
                                (8.0, 8.0))
            i += length
    meshes = [np.concatenate(quads)]
    # clutter: poles, bins and parked cars at the kerbs
    for s in np.arange(line.arc[0] + 4.0, line.arc[-1], 7.0):
        if rng.random() < 0.3:
            continue
        p, f, r = line.at(float(s + rng.uniform(-2, 2)))
        side = 1.0 if rng.random() < 0.5 else -1.0
        kind = rng.random()
        if kind < 0.4:
            size, lateral = np.array([0.2, 3.5, 0.2]), half_road + 0.6
        elif kind < 0.7:
            size, lateral = rng.uniform([0.5, 0.6, 0.5], [1.2, 1.4, 1.2]), half_road + rng.uniform(0.8, 2.5)
        else:
            size, lateral = np.array([1.8, 1.5, 4.2]) * rng.uniform(0.9, 1.1), half_road - 1.2
        layer = _LAYER[_CLUTTER[int(rng.integers(len(_CLUTTER)))]]
        rotation = np.column_stack([r, _DOWN, f])
        centre = p + r * side * lateral + _DOWN * (h - size[1] / 2)
        meshes.append(_placed(box_mesh(size, layer, tile=1.5), rotation, centre))
    objects = []
    n_frames = poses.shape[0]
    for j in range(n_moving):
        size = np.array([1.8, 1.5, 4.2])
        start, speed = rng.uniform(12.0, 40.0), rng.uniform(0.3, 1.6)
        lateral = 2.5 if j % 2 == 0 else -2.5
        track = []
        for k in range(n_frames):
            p, f, r = line.at(start + speed * k)
            pose = np.eye(4)
            pose[:3, :3] = np.column_stack([r, _DOWN, f])
            pose[:3, 3] = p + r * lateral + _DOWN * (h - size[1] / 2)
            track.append(pose)
        objects.append(MovingObject(box_mesh(size, _LAYER["object"], tile=1.5), np.array(track)))
    return np.concatenate(meshes).astype(np.float32), objects


def open_world(poses: np.ndarray, rng: np.random.Generator, n_moving: int) -> tuple[np.ndarray, list[MovingObject]]:
    """The ``open`` world around camera-to-world ``poses``: scattered boxes in a textured enclosure."""
    path = poses[:, :3, 3]
    low, high = path.min(axis=0) - 25.0, path.max(axis=0) + 25.0
    meshes = []
    centre, half = (low + high) / 2, (high - low) / 2 + 15.0
    room = box_mesh(2 * half, _LAYER["sky_box"], tile=30.0)  # large tiles: far walls keep coarse, distinct texture
    meshes.append(_placed(room, np.eye(3), centre))
    count = int(min(4000, 0.004 * np.prod(high - low) + 150))
    centres = rng.uniform(low, high, (count, 3))
    gap = np.min(np.linalg.norm(centres[:, None, :] - path[None, ::5, :], axis=2), axis=1)
    for c in centres[gap > 3.5]:
        size = rng.uniform(0.6, 3.0, 3)
        axis = rng.standard_normal(3)
        angle = rng.uniform(0, np.pi)
        rotation = so3_exp(axis / np.linalg.norm(axis) * angle)
        layer = _LAYER[_CLUTTER[int(rng.integers(len(_CLUTTER)))]] if rng.random() < 0.7 else \
            _LAYER[_FACADES[int(rng.integers(len(_FACADES)))]]
        meshes.append(_placed(box_mesh(size, layer, tile=1.5), rotation, c))
    objects = []
    n_frames = poses.shape[0]
    for _ in range(n_moving):
        k0 = int(rng.integers(0, n_frames))
        start = poses[k0, :3, 3] + poses[k0, :3, 2] * rng.uniform(5.0, 10.0)
        velocity = rng.standard_normal(3) * 0.15
        track = []
        for k in range(n_frames):
            pose = np.eye(4)
            pose[:3, 3] = start + velocity * (k - k0)
            track.append(pose)
        objects.append(MovingObject(box_mesh(rng.uniform(1.0, 2.5, 3), _LAYER["object"], tile=1.5), np.array(track)))
    return np.concatenate(meshes).astype(np.float32), objects
