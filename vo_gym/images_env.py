"""``StereoVOImagesEnv``: the stereo-VO environment on matches an image front end found.

The observation, action, reward and info are :class:`vo_gym.env.StereoVOEnv`'s, built by the
same code (the features of :mod:`vo_gym.features`, the estimator core, the rewards): every
sampler that runs on ``vo_gym/StereoVO-v0`` runs on ``vo_gym/StereoVOImages-v0`` unchanged.
What differs is where a step's frame pair comes from: stereo images rendered along a simulator
trajectory (:class:`stereovo.sequences.RenderedSequence`, the default) or a recorded sequence
with known poses (``source=`` a :class:`stereovo.sequences.KittiOdometry` or any frame
sequence), matched by :mod:`stereovo.frontend`. Its outliers are the matcher's own: repetitive
texture, occlusion, wrong stereo pairs, moving objects.
"""

from __future__ import annotations

import dataclasses
from collections import OrderedDict
from typing import Any

import numpy as np

from stereovo.options import Choice, Integer, Number, Option, check_options, value_repr
from stereovo.simulation import Frame
from vo_gym.env import StereoVOEnv

__all__ = ["StereoVOImagesEnv", "EpisodeFrames", "ReplayedFrames"]

_RULES: dict[str, Option] = {
    "n_frames": Integer(low=1, high=100_000),
    "max_correspondences": Integer(low=3, high=100_000),
    "resolution": Choice(choices=("kitti", "vga")),
    "moving_objects": Integer(low=0, high=32),
    "image_noise": Number(low=0.0, high=50.0),
    "texture_seed": Integer(low=0, allow_none=True),
    "cached_episodes": Integer(low=0, high=64),
}
# StereoVOEnv's simulator knobs that images decide for themselves (the camera: the resolution's or the source's)
_SIMULATOR_ONLY = ("n_correspondences", "outlier_ratio", "outlier_mix", "outliers", "noise_dof", "score_auc", "z_min",
                   "z_max", "noise_sigma", "camera")


def top_rows(frame: Frame, index: int, limit: int) -> Frame:
    """``frame`` renumbered ``index``, keeping at most ``limit`` rows: the best scored, in their order."""
    if frame.n <= limit:
        return dataclasses.replace(frame, index=index)
    keep = np.sort(np.argsort(-frame.scores, kind="stable")[:limit])
    truth = frame.truth
    if truth is not None:
        truth = dataclasses.replace(truth, inlier=truth.inlier[keep], outlier_kind=truth.outlier_kind[keep],
                                    outlier_ratio=float(1.0 - truth.inlier[keep].mean()))
    return dataclasses.replace(frame, index=index, prev=frame.prev[keep], curr=frame.curr[keep],
                               scores=frame.scores[keep], truth=truth)


def _check_source(source: Any, prefix: str) -> None:
    if getattr(source, "true_poses", None) is None or not hasattr(source, "frame"):
        raise ValueError(f"{prefix}source must be a frame sequence with known poses (true_poses), "
                         f"got {value_repr(source)}: the rewards and the info need the true motion")


class ReplayedFrames:
    """Frames computed once (rendered, matched), served as a frame sequence for ``source=``, so that
    every sampler of a comparison sees the identical frames.

    Args:
        frames: the frame pairs ``1 .. len(frames)`` in order. camera: their rig.
        true_poses: ``(len(frames) + 1, 4, 4)`` camera-to-world poses. noise_sigma: their pixel noise (px).
    """

    def __init__(self, frames: list[Frame], camera: Any, true_poses: Any, noise_sigma: float) -> None:
        self.frames, self.camera, self.true_poses, self.noise_sigma = frames, camera, true_poses, noise_sigma

    def __len__(self) -> int:
        return len(self.frames)

    def frame(self, k: int) -> Frame:
        return self.frames[k - 1]


class EpisodeFrames:
    """One episode's frames: frame pairs ``offset + 1 .. offset + n_frames`` of a source sequence,
    numbered ``1 .. n_frames``, each computed on first use (in the step that needs it) and kept.

    Attributes:
        camera: the source's rig. true_poses: ``(n_frames + 1, 4, 4)`` the window's poses.
    """

    def __init__(self, source: Any, offset: int, n_frames: int, limit: int) -> None:
        self.source, self.offset, self.limit = source, int(offset), int(limit)
        self.camera = source.camera
        self.true_poses = np.asarray(source.true_poses[self.offset:self.offset + n_frames + 1])
        self._n = int(n_frames)
        self._frames: dict[int, Frame] = {}

    def __len__(self) -> int:
        return self._n

    def frame(self, k: int) -> Frame:
        if not 1 <= k <= self._n:
            raise IndexError(f"frame index must be an integer in [1, {self._n}], got {k!r}")
        if k not in self._frames:
            self._frames[k] = top_rows(self.source.frame(self.offset + k), k, self.limit)
        return self._frames[k]

    def __iter__(self):
        for k in range(1, self._n + 1):
            yield self.frame(k)


class StereoVOImagesEnv(StereoVOEnv):
    """Stereo visual odometry on images; the agent proposes RANSAC sampling priors.

    Everything of :class:`vo_gym.env.StereoVOEnv` holds (spaces, sampling modes, rewards, info,
    estimator arguments), with one step's frame pair made from images:

    - ``source=None`` (default): each ``reset`` renders a new world along a new simulator
      trajectory of the ``preset`` from the reset's seed (:class:`~stereovo.sequences.RenderedSequence`
      at ``resolution``, with ``moving_objects``, ``image_noise``, ``speed``, ``world``).
    - ``source=`` a frame sequence with ``true_poses`` (a :class:`~stereovo.sequences.KittiOdometry`,
      a :class:`~stereovo.sequences.RenderedSequence`, ...) or a source string (``"rendered"``,
      ``"kitti:PATH[:SEQ]"``): each episode is ``n_frames`` consecutive frame pairs of it from a
      start the reset's seed draws.

    A frame has as many matches as the front end found, at most ``max_correspondences`` (the
    observation's rows; beyond it the best scored are kept); the rest of the rows are padding
    (``mask`` 0). The rendering and the matching happen in the step that needs the frame, so
    they count in the step's time; the frames an episode's seed determines are kept for the
    last ``cached_episodes`` seeds, and the procedural textures for ``texture_seed`` (None: a
    fresh set per episode, drawn from its seed).

    The info's ``outlier_ratio`` is the realised share of the frame's rows that its labels mark as
    outliers (after the cut to ``max_correspondences``; 1.0 for a frame without matches): images
    draw no contamination, so it is not the simulated environments' drawn epsilon. A row whose
    match score is NaN or inf is a failed match, a row without depth (see
    :class:`vo_gym.env.StereoVOEnv`, Observation Space).

    Args:
        source: see above. n_frames: steps per episode. max_correspondences: observation rows.
        preset, resolution, moving_objects, image_noise, speed, world: the rendered world's (None:
            ``"car"``, ``"kitti"``, 0, 2.0, the preset's speed and world).
        frontend_options: :class:`~stereovo.frontend.FrontendOptions` fields as a dict: the front
            end of the rendered world or of a source string.
        estimator_noise_sigma: the pixel noise the estimator and the features assume; None: the
            source's ``noise_sigma``.
        **kwargs: any other :class:`vo_gym.env.StereoVOEnv` argument (``sampling``, ``reward_mode``,
            ``method``, ``budget``, estimator options, ...). Its simulator-only arguments
            (``n_correspondences``, ``outlier_ratio``, ``outliers``, ``noise_dof``, ``score_auc``,
            ``camera``, ...) are refused: images decide them (the camera is the resolution's or the
            source's).

    The rendered world's arguments are checked at construction by the rules of
    :class:`~stereovo.sequences.RenderedSequence` (e.g. ``speed`` in (0, 10] m/frame), not at the
    first reset.

    With a ``source``, the frames and the camera are the source's: the rendered world's arguments
    (``preset``, ``resolution``, ``moving_objects``, ``image_noise``, ``speed``, ``world``, a
    ``texture_seed`` other than 0) would be ignored and are refused, even where they agree with the
    source; so is ``frontend_options`` with a sequence object, which matched its frames with its own.

    Raises:
        ValueError: a bad argument, named, or one that ``source`` makes meaningless; TypeError: an
            unknown or simulator-only keyword.
    """

    def __init__(self, source: Any = None, n_frames: int = 100, max_correspondences: int = 1000,
                 preset: str | None = None, resolution: str | None = None, moving_objects: int | None = None,
                 image_noise: float | None = None, speed: float | None = None, world: str | None = None,
                 frontend_options: dict | None = None, texture_seed: int | None = 0, cached_episodes: int = 2,
                 estimator_noise_sigma: float | None = None, **kwargs: Any) -> None:
        prefix = f"{type(self).__name__}: "  # the class the user made, also when it is a subclass
        refused = sorted(set(kwargs) & set(_SIMULATOR_ONLY))
        if refused:
            raise TypeError(f"{prefix}{refused} are simulator settings; on images the front end decides them "
                            "(and the camera is the resolution's or the source's)")
        if source is not None and not isinstance(source, str):
            _check_source(source, prefix)
            if frontend_options is not None:
                raise ValueError(f"{prefix}frontend_options={frontend_options!r} would be ignored: source="
                                 f"{type(source).__name__} matched its frames with its own front end (they apply to "
                                 "the rendered world or a source string)")
        if source is not None:
            world_given = {name: value for name, value in (
                ("preset", preset), ("resolution", resolution), ("moving_objects", moving_objects),
                ("image_noise", image_noise), ("speed", speed), ("world", world)) if value is not None}
            if texture_seed != 0:
                world_given["texture_seed"] = texture_seed
            if world_given:
                what = repr(source) if isinstance(source, str) else type(source).__name__
                raise ValueError(f"{prefix}{', '.join(f'{k}={v!r}' for k, v in world_given.items())} would be "
                                 f"ignored: they set the world rendered when source is None, and source={what} "
                                 "brings its own frames and camera; leave them out")
        preset = "car" if preset is None else preset
        resolution = "kitti" if resolution is None else resolution
        moving_objects = 0 if moving_objects is None else moving_objects
        image_noise = 2.0 if image_noise is None else image_noise
        checked = check_options(_RULES, dict(n_frames=n_frames, max_correspondences=max_correspondences,
                                             resolution=resolution, moving_objects=moving_objects,
                                             image_noise=image_noise, texture_seed=texture_seed,
                                             cached_episodes=cached_episodes), prefix=prefix)
        if source is None:
            # RenderedSequence's own rules for what reset hands it (one more frame pair: the spare one of
            # truncation), checked now rather than at the first reset
            from stereovo.sequences.rendered import RENDER_RULES

            check_options(RENDER_RULES, dict(preset=preset, world=world, resolution=checked["resolution"],
                                             moving_objects=checked["moving_objects"], image_noise=checked["image_noise"],
                                             speed=speed, texture_seed=checked["texture_seed"]), prefix=prefix)
            most = RENDER_RULES["n_frames"].high
            if checked["n_frames"] + 1 > most:
                raise ValueError(f"{prefix}n_frames must be at most {most - 1} for the rendered world (an episode "
                                 f"renders n_frames + 1 frame pairs, at most {most}), got {checked['n_frames']}")
        if frontend_options is not None and not isinstance(frontend_options, dict):
            raise ValueError(f"{prefix}frontend_options must be a dict of FrontendOptions fields, "
                             f"got {value_repr(frontend_options)}")
        from stereovo.frontend import FrontendOptions
        from stereovo.sequences.rendered import RESOLUTIONS

        try:
            self.frontend_options = FrontendOptions(**(frontend_options or {}))
        except TypeError as err:
            raise TypeError(f"{prefix}frontend_options: {err}") from None
        if isinstance(source, str):
            from stereovo.sequences import open_source

            source = open_source(source, options=self.frontend_options)
        if source is not None:
            _check_source(source, prefix)
            if len(source) < checked["n_frames"] + 1:
                raise ValueError(f"{prefix}source has {len(source)} frame pairs; an episode of n_frames="
                                 f"{checked['n_frames']} needs n_frames + 1")
            camera, noise = source.camera, float(getattr(source, "noise_sigma", 0.5))
        else:
            camera, noise = RESOLUTIONS[checked["resolution"]], 0.5
        self.source = source
        self.render_settings = dict(preset=preset, resolution=checked["resolution"],
                                    moving_objects=checked["moving_objects"], image_noise=checked["image_noise"],
                                    speed=speed, world=world)
        self.texture_seed = checked["texture_seed"]
        self.cached_episodes = checked["cached_episodes"]
        M = checked["max_correspondences"]
        super().__init__(n_frames=checked["n_frames"], n_correspondences=M, max_correspondences=M, preset=preset,
                         world=world, speed=speed, camera=camera, noise_sigma=noise,
                         estimator_noise_sigma=estimator_noise_sigma, **kwargs)
        self._episodes: OrderedDict[int, EpisodeFrames] = OrderedDict()

    def make_sequence(self, seed: int) -> EpisodeFrames:
        """The episode of a reset's seed: rendered from it, or a window of the source it places."""
        if seed in self._episodes:
            self._episodes.move_to_end(seed)
            return self._episodes[seed]
        n = self.sim_config.n_frames + 1  # a spare frame pair: the observation returned at truncation
        if self.source is None:
            from stereovo.sequences.rendered import RenderedSequence

            rendered = RenderedSequence(n_frames=n, seed=seed, texture_seed=self.texture_seed,
                                        options=self.frontend_options, **self.render_settings)
            episode = EpisodeFrames(rendered, 0, n, self.max_correspondences)
        else:
            offset = int(np.random.default_rng(seed).integers(0, len(self.source) - n + 1))
            episode = EpisodeFrames(self.source, offset, n, self.max_correspondences)
        self._episodes[seed] = episode
        while len(self._episodes) > max(self.cached_episodes, 1):
            _, old = self._episodes.popitem(last=False)
            if old.source is not self.source and hasattr(old.source, "close"):
                old.source.close()
        return episode

    def close(self) -> None:
        for episode in self._episodes.values():
            if episode.source is not self.source and hasattr(episode.source, "close"):
                episode.source.close()
        self._episodes.clear()
        super().close()
