"""Frame-pair sequences from images -- rendered or a user's own -- in one interface with the simulator's.

- :mod:`~stereovo.sequences.base`: the interface (:class:`FrameSequence`), the simulator's
  adapter (:class:`SimulatedSequence`) and the base of image sequences (:class:`ImageSequence`:
  images -> front end -> :class:`~stereovo.simulation.Frame`).
- :mod:`~stereovo.sequences.rendered`: :class:`RenderedSequence`, a procedural world rendered
  along the simulator's trajectories, with ground-truth poses, depth maps and match labels;
  built from :mod:`~stereovo.sequences.world` (geometry), :mod:`~stereovo.sequences.textures`
  (procedural textures), :mod:`~stereovo.sequences.rendering` (moderngl + EGL on the CPU) and
  :mod:`~stereovo.sequences.labels` (per-match labels from depth and motion).
- :mod:`~stereovo.sequences.contamination`: :func:`contaminate`, an image frame's outlier
  fraction raised to a chosen epsilon with wrong temporal matches (the contamination sweeps).
- :mod:`~stereovo.sequences.kitti`: :class:`KittiOdometry`, a KITTI odometry sequence on disk.
- :mod:`~stereovo.sequences.sources`: :func:`open_source` (``"rendered"``, ``"kitti:PATH[:SEQ]"``)
  and :func:`run_image_odometry` (odometry and drift over any of them).

Rendering needs the ``render`` extra and EGL; images need the ``images`` extra (OpenCV).
Importing this package imports neither until a sequence is made.
"""

from stereovo.sequences.base import FRONTEND_SCORE_AUC, FrameSequence, ImageSequence, SimulatedSequence, as_frame_sequence
from stereovo.sequences.contamination import contaminate

__all__ = [
    "FRONTEND_SCORE_AUC",
    "FrameSequence",
    "ImageSequence",
    "KittiOdometry",
    "RenderedSequence",
    "SimulatedSequence",
    "as_frame_sequence",
    "contaminate",
    "open_source",
    "run_image_odometry",
]


def __getattr__(name: str):
    # lazy: the renderer and the KITTI loader import their optional dependencies when first used
    if name == "RenderedSequence":
        from stereovo.sequences.rendered import RenderedSequence

        return RenderedSequence
    if name == "KittiOdometry":
        from stereovo.sequences.kitti import KittiOdometry

        return KittiOdometry
    if name in ("open_source", "run_image_odometry"):
        from stereovo.sequences import sources

        return getattr(sources, name)
    raise AttributeError(f"module 'stereovo.sequences' has no attribute {name!r}")
