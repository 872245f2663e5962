""":class:`RenderedSequence`: a textured world rendered along a simulator trajectory, with truth.

The trajectory is the simulator's own (:class:`stereovo.simulation.Sequence`'s ``true_poses``
for the preset, frame count, speed and seed); the world is built along it
(:mod:`stereovo.sequences.world`) with procedural textures (:mod:`stereovo.sequences.textures`)
and rendered headless on the CPU (:mod:`stereovo.sequences.rendering`). Each image gets a fixed
pattern of sensor noise, a seeded crop of one noise field. Everything comes from the seed: the
same seed renders the same images (on one machine and Mesa build) and gives the same matches.
"""

from __future__ import annotations

import functools
from collections import OrderedDict
from typing import Any

import numpy as np

from stereovo.camera import StereoCamera
from stereovo.frontend import Matches
from stereovo.geometry import invert_transform, relative_motion
from stereovo.options import Choice, Integer, Number, Option, check_options
from stereovo.sequences.base import ImageSequence
from stereovo.sequences.labels import label_matches
from stereovo.sequences.rendering import Renderer
from stereovo.sequences.textures import make_textures
from stereovo.sequences.world import open_world, street_world
from stereovo.simulation import PRESETS, FrameTruth, Sequence, SimulationConfig

RESOLUTIONS: dict[str, StereoCamera] = {
    "kitti": StereoCamera(),
    "vga": StereoCamera(fx=525.0, fy=525.0, cx=319.5, cy=239.5, baseline=0.3, width=640, height=480),
}
"""Cameras by resolution name: KITTI-like 1241x376 (the simulator's default rig) and 640x480."""

RENDER_RULES: dict[str, Option] = {
    "preset": Choice(choices=tuple(sorted(PRESETS))),
    "world": Choice(choices=("street", "open"), allow_none=True),
    "n_frames": Integer(low=1, high=100_000),
    "resolution": Choice(choices=tuple(RESOLUTIONS)),
    "moving_objects": Integer(low=0, high=32),
    "image_noise": Number(low=0.0, high=50.0, unit="grey levels"),
    "speed": Number(low=0.0, high=10.0, low_open=True, unit="m/frame", allow_none=True),
    "texture_seed": Integer(low=0, allow_none=True),
}
"""The rules of :class:`RenderedSequence`'s arguments (the image environment checks them at construction too)."""


@functools.lru_cache(maxsize=4)
def shared_textures(texture_seed: int) -> np.ndarray:
    """The texture layers of ``texture_seed``, made once per process (read-only)."""
    textures = make_textures(np.random.default_rng(texture_seed))
    textures.setflags(write=False)
    return textures


_NAMESPACE = 0x5245  # keeps the renderer's child seeds apart from other users of the same seed
_NOISE_MARGIN = 64


class RenderedSequence(ImageSequence):
    """Stereo images rendered along a simulator trajectory, matched by the front end, with truth.

    Args:
        preset: the motion, ``"car"`` or ``"free"`` (:data:`stereovo.simulation.PRESETS`).
        n_frames: frame pairs F (F + 1 image pairs).
        resolution: ``"kitti"`` (1241x376) or ``"vga"`` (640x480), see :data:`RESOLUTIONS`;
            ignored when ``camera`` is given.
        seed: an int, a SeedSequence or None (fresh entropy).
        moving_objects: boxes moving on their own (cars in the next lane for ``car``).
        world: ``"street"`` or ``"open"``; None: street for ``car``, open for ``free``.
        image_noise: std of the sensor noise added to each image (grey levels).
        speed: mean speed (m/frame) overriding the preset's.
        camera: a rig overriding ``resolution``.
        noise_sigma: the pixel noise (px) the frames declare to the estimator.
        texture_seed: None draws the textures from ``seed``; an int draws them from it instead, once
            per process (worlds of many seeds then share one texture set, and skip drawing it).
        **frontend_options: :class:`~stereovo.frontend.FrontendOptions` fields.

    Attributes:
        true_poses: ``(F+1, 4, 4)`` camera-to-world poses of the left camera, the first the identity.
        object_poses: ``(J, F+1, 4, 4)`` object-to-world poses of the moving objects.

    Raises:
        ValueError: a bad argument, named. :class:`~stereovo.sequences.rendering.RenderingUnavailable`
        when no headless OpenGL context can be made.
    """

    def __init__(self, preset: str = "car", n_frames: int = 100, resolution: str = "kitti",
                 seed: int | np.random.SeedSequence | None = 0, moving_objects: int = 0, world: str | None = None,
                 image_noise: float = 2.0, speed: float | None = None, camera: StereoCamera | None = None,
                 noise_sigma: float = 0.5, texture_seed: int | None = None, **frontend_options: Any) -> None:
        checked = check_options(RENDER_RULES, dict(preset=preset, world=world, n_frames=n_frames, resolution=resolution,
                                             moving_objects=moving_objects, image_noise=image_noise, speed=speed,
                                             texture_seed=texture_seed),
                                prefix="RenderedSequence: ")
        if camera is not None and not isinstance(camera, StereoCamera):
            raise ValueError(f"RenderedSequence: camera must be a StereoCamera or None, got {type(camera).__name__}")
        camera = RESOLUTIONS[checked["resolution"]] if camera is None else camera
        super().__init__(camera, noise_sigma=noise_sigma, **frontend_options)
        self.preset = checked["preset"]
        self.world = checked["world"] or ("street" if self.preset == "car" else "open")
        self.seed = seed
        self.image_noise = float(checked["image_noise"])
        root = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
        self._root = root
        config = SimulationConfig(preset=self.preset, n_frames=checked["n_frames"], speed=checked["speed"],
                                  camera=camera)
        self.true_poses = Sequence(config, root).true_poses
        world_rng, texture_rng, noise_rng = (np.random.default_rng(s) for s in self._spawn(("world", 0), 3))
        build = street_world if self.world == "street" else open_world
        vertices, objects = build(self.true_poses, world_rng, checked["moving_objects"])
        self.object_poses = np.array([o.poses for o in objects]).reshape(len(objects), self.n_images(), 4, 4)
        seeded = checked["texture_seed"]
        textures = make_textures(texture_rng) if seeded is None else shared_textures(seeded)
        self._renderer = Renderer(camera, vertices, [o.mesh for o in objects], textures)
        h, w = int(camera.height), int(camera.width)
        self._noise = (noise_rng.standard_normal((h + _NOISE_MARGIN, w + _NOISE_MARGIN)) * self.image_noise).astype(
            np.float32)
        self._rendered: OrderedDict[int, tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = OrderedDict()

    def _spawn(self, key: tuple[str, int], count: int) -> list[np.random.SeedSequence]:
        root = self._root
        tag = sum(ord(c) << (8 * i) for i, c in enumerate(key[0][:4]))
        return [np.random.SeedSequence(root.entropy, spawn_key=(*root.spawn_key, _NAMESPACE, tag, key[1], i))
                for i in range(count)]

    def n_images(self) -> int:
        return int(self.true_poses.shape[0])

    def _render(self, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        if k in self._rendered:
            self._rendered.move_to_end(k)
            return self._rendered[k]
        pose = self.true_poses[k]
        objects = [p[k] for p in self.object_poses]
        right_pose = pose.copy()
        right_pose[:3, 3] += pose[:3, 0] * self.camera.baseline
        left, depth, ids = self._renderer.draw(pose, objects, True)
        right = self._renderer.draw(right_pose, objects, False)
        if self.image_noise > 0:
            offsets = np.random.default_rng(self._spawn(("noise", k), 1)[0]).integers(0, _NOISE_MARGIN, 4)
            left = self._noisy(left, offsets[0], offsets[1])
            right = self._noisy(right, offsets[2], offsets[3])
        entry = (left, right, depth, ids)
        self._rendered[k] = entry
        while len(self._rendered) > self._cache_size:
            self._rendered.popitem(last=False)
        return entry

    def _noisy(self, image: np.ndarray, dy: int, dx: int) -> np.ndarray:
        h, w = image.shape
        noisy = image + self._noise[dy:dy + h, dx:dx + w]
        return np.clip(np.rint(noisy), 0, 255).astype(np.uint8)

    def load_images(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        left, right, _, _ = self._render(k)
        return left, right

    def depth(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """``(depth, ids)`` of image pair k's left image: depth ``(H, W)`` float32 (m; 0 where
        nothing was drawn) and object ids ``(H, W)`` int16 (0 static, j + 1 moving object j)."""
        _, _, depth, ids = self._render(self._check_image_index(k))
        return depth, ids

    def motions(self, k: int) -> dict[int, tuple[np.ndarray, np.ndarray]]:
        """``id -> (R, t)`` taking points of each object from camera k-1 to camera k (id 0: the world)."""
        pose_prev, pose_curr = self.true_poses[k - 1], self.true_poses[k]
        out = {0: relative_motion(pose_prev, pose_curr)}
        for j, poses in enumerate(self.object_poses):
            # camera k-1 -> world -> object (at k-1) -> world (at k) -> camera k
            A = invert_transform(pose_curr) @ poses[k] @ invert_transform(poses[k - 1]) @ pose_prev
            out[j + 1] = (A[:3, :3], A[:3, 3])
        return out

    def label(self, k: int, matches: Matches) -> FrameTruth:
        depth, ids = self.depth(k - 1)
        inlier, kind = label_matches(matches.prev, matches.curr, self.camera, depth, ids, self.motions(k))
        R, t = relative_motion(self.true_poses[k - 1], self.true_poses[k])
        return FrameTruth(rotation=R, translation=t, inlier=inlier, outlier_kind=kind,
                          pose_prev=self.true_poses[k - 1], pose_curr=self.true_poses[k],
                          outlier_ratio=float(1.0 - inlier.mean()) if inlier.size else 1.0)

    def close(self) -> None:
        """Free the renderer's GL objects (the sequence can no longer render)."""
        if getattr(self, "_renderer", None) is not None:
            self._renderer.release()
            self._renderer = None

    def __del__(self) -> None:
        try:
            self.close()
        except Exception:  # the GL context may be gone at interpreter exit
            pass

    def __repr__(self) -> str:
        return (f"RenderedSequence(preset={self.preset!r}, n_frames={len(self)}, "
                f"size={self.camera.width}x{self.camera.height}, seed={self.seed!r})")
