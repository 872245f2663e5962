"""Procedural grey textures of the rendered world, drawn from a seed (no downloads).

Each texture is a square ``uint8`` layer of one texture array: multi-octave value noise for
grain, and drawn structure on top -- road markings, paving tiles, brick courses, window grids
(repetitive on purpose: a window looks like its neighbours, which is where real matchers go
wrong), and scattered shapes on clutter. Every random choice comes from the passed generator.
"""

from __future__ import annotations

import numpy as np

TEXTURE_SIZE = 512
"""Side of every texture layer (px)."""

LAYERS: tuple[str, ...] = (
    "road", "sidewalk", "facade_brick", "facade_windows", "facade_panels", "facade_stone",
    "clutter_blobs", "clutter_checker", "clutter_stripes", "clutter_marks", "object", "sky_box",
)
"""Texture layers by index; the world's meshes name them."""


def _cv2():
    import cv2

    return cv2


def value_noise(rng: np.random.Generator, size: int, octaves: tuple[int, ...], weights: tuple[float, ...]) -> np.ndarray:
    """``(size, size)`` float32 noise in about [-1, 1]: random grids of ``octaves`` cells per side,
    upsampled smoothly and summed with ``weights``; tiles seamlessly (the grids wrap)."""
    cv2 = _cv2()
    out = np.zeros((size, size), np.float32)
    for cells, weight in zip(octaves, weights):
        grid = rng.uniform(-1.0, 1.0, (cells, cells)).astype(np.float32)
        wrapped = np.pad(grid, 2, mode="wrap")
        scale = size / cells
        big = cv2.resize(wrapped, None, fx=scale, fy=scale, interpolation=cv2.INTER_CUBIC)
        offset = int(round(2 * scale))
        out += weight * big[offset:offset + size, offset:offset + size]
    return out


def _grain(rng: np.random.Generator, size: int, amount: float) -> np.ndarray:
    return amount * value_noise(rng, size, (4, 16, 64, 256), (0.35, 0.3, 0.2, 0.15))


def _finish(base: float, layer: np.ndarray) -> np.ndarray:
    return np.clip(base + layer, 0, 255).astype(np.uint8)


def _shapes(rng: np.random.Generator, image: np.ndarray, count: int, min_side: int, max_side: int) -> None:
    """Draw ``count`` filled rectangles and circles of random grey into ``image`` in place."""
    cv2 = _cv2()
    size = image.shape[0]
    for _ in range(count):
        x, y = (int(v) for v in rng.integers(0, size, 2))
        a, b = (int(v) for v in rng.integers(min_side, max_side, 2))
        grey = float(rng.uniform(-90, 90))
        if rng.random() < 0.5:
            cv2.rectangle(image, (x, y), (x + a, y + b), grey, -1)
        else:
            cv2.circle(image, (x, y), a // 2, grey, -1)


def make_textures(rng: np.random.Generator, size: int = TEXTURE_SIZE) -> np.ndarray:
    """``(len(LAYERS), size, size)`` uint8 texture layers (see :data:`LAYERS`)."""
    cv2 = _cv2()
    layers = []
    s = size

    road = _grain(rng, s, 60.0)
    _shapes(rng, road, 40, 4, 30)  # patches and stains
    road[:, s // 2 - 6:s // 2 + 6] += 110.0  # a dashed centre line, one dash per tile
    road[: s // 3, s // 2 - 6:s // 2 + 6] -= 110.0
    layers.append(_finish(90, road))

    walk = _grain(rng, s, 40.0)
    tile = s // 8
    walk[::tile, :] -= 70.0
    walk[:, ::tile] -= 70.0
    walk[1::tile, :] -= 40.0
    walk[:, 1::tile] -= 40.0
    _shapes(rng, walk, 25, 3, 16)
    layers.append(_finish(150, walk))

    brick = _grain(rng, s, 35.0)
    course, length = s // 32, s // 12
    for row in range(32):
        y = row * course
        brick[y:y + 2, :] -= 60.0
        shift = (length // 2) * (row % 2)
        for x in range(shift, s, length):
            brick[y:y + course, x:x + 2] -= 60.0
        brick[y + 2:y + course, :] += float(rng.uniform(-15, 15))
    layers.append(_finish(140, brick))

    windows = _grain(rng, s, 30.0)
    step = s // 4  # four identical-looking windows per tile and row: repetitive on purpose
    for gy in range(4):
        for gx in range(4):
            x0, y0 = gx * step + step // 5, gy * step + step // 5
            x1, y1 = x0 + 3 * step // 5, y0 + 3 * step // 5
            windows[y0:y1, x0:x1] = -80.0 + float(rng.uniform(-8, 8))
            windows[y0 - 4:y0, x0 - 4:x1 + 4] += 60.0  # lintel
            windows[(y0 + y1) // 2 - 2:(y0 + y1) // 2 + 2, x0:x1] += 90.0  # glazing bar
            windows[y0:y1, (x0 + x1) // 2 - 2:(x0 + x1) // 2 + 2] += 90.0
    layers.append(_finish(160, windows))

    panels = _grain(rng, s, 45.0)
    for _ in range(12):
        x, y = (int(v) for v in rng.integers(0, s - 64, 2))
        w, h = (int(v) for v in rng.integers(24, 96, 2))
        cv2.rectangle(panels, (x, y), (x + w, y + h), float(rng.uniform(-70, 70)), 3)
    _shapes(rng, panels, 30, 6, 40)
    layers.append(_finish(120, panels))

    stone = _grain(rng, s, 70.0)
    for _ in range(160):
        x, y = (int(v) for v in rng.integers(0, s, 2))
        r = int(rng.integers(6, 22))
        cv2.circle(stone, (x, y), r, float(rng.uniform(-60, 60)), -1)
        cv2.circle(stone, (x, y), r, -80.0, 1)
    layers.append(_finish(130, stone))

    blobs = _grain(rng, s, 50.0)
    _shapes(rng, blobs, 120, 8, 60)
    layers.append(_finish(128, blobs))

    checker = _grain(rng, s, 30.0)
    cell = s // 16
    yy, xx = np.mgrid[0:s, 0:s]
    checker += np.where(((yy // cell) + (xx // cell)) % 2 == 0, 70.0, -70.0).astype(np.float32)
    _shapes(rng, checker, 15, 6, 30)
    layers.append(_finish(128, checker))

    stripes = _grain(rng, s, 40.0)
    stripes += 60.0 * np.sign(np.sin(xx * (2 * np.pi * 12 / s))).astype(np.float32)
    _shapes(rng, stripes, 40, 6, 40)
    layers.append(_finish(128, stripes))

    marks = _grain(rng, s, 60.0)
    for _ in range(120):  # strokes like signage and graffiti
        x, y = (int(v) for v in rng.integers(0, s, 2))
        dx, dy = (int(v) for v in rng.integers(-40, 40, 2))
        cv2.line(marks, (x, y), (x + dx, y + dy), float(rng.uniform(-100, 100)), int(rng.integers(2, 6)))
    layers.append(_finish(128, marks))

    obj = _grain(rng, s, 50.0)
    _shapes(rng, obj, 60, 10, 70)
    layers.append(_finish(100, obj))

    sky = _grain(rng, s, 80.0)
    _shapes(rng, sky, 200, 4, 40)
    layers.append(_finish(128, sky))
    return np.stack(layers)
