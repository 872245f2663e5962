"""The samplers shipped inside the package: their names, their kind and where their files are.

Torch-free, so that the command line can list and check the names (``--help``, argument errors)
without loading torch; loading a sampler is :func:`agents.checkpoint.load_sampler` (one-shot) or
:func:`agents.adaptive.checkpoint.load_adaptive` (in-frame).

Two kinds:

- *one-shot* (:data:`ONE_SHOT_SAMPLERS`): a network that scores every match once per frame from the
  features (NG-RANSAC-style training, or the PPO actor); its logits become the frame's sampling
  priors;
- *in-frame* (:data:`IN_FRAME_SAMPLERS`): a network that acts inside one frame's RANSAC loop, on the
  loop's evidence (``vo_gym/StereoVOAdaptive-v0``), and chooses when to stop.

Each file is ``agents/checkpoints/NAME.pt``, found with :mod:`importlib.resources` so that it is
found from any directory and any kind of install.
"""

from __future__ import annotations

import importlib.resources
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # importlib.resources.abc is Python 3.11+
    from importlib.resources.abc import Traversable

SHIPPED_PACKAGE = "agents"
SHIPPED_FOLDER = "checkpoints"

ONE_SHOT = "one-shot"
IN_FRAME = "in-frame"

ONE_SHOT_SAMPLERS: tuple[str, ...] = (
    "ngransac-supervised", "ngransac-self-supervised", "ngransac-self-supervised-smooth", "ppo",
)
"""The shipped one-shot samplers (``vo-gym evaluate --agent NAME``, ``vo-gym vo --agent NAME``)."""

IN_FRAME_SAMPLERS: tuple[str, ...] = ("adaptive-pg-prior", "adaptive-pg")
"""The shipped in-frame samplers (``vo-gym evaluate --adaptive --adaptive-sampler NAME``)."""

SHIPPED_SAMPLERS = ONE_SHOT_SAMPLERS
"""What :func:`agents.checkpoint.load_sampler` accepts by name: the one-shot samplers."""


def sampler_kind(name: str) -> str:
    """``"one-shot"`` or ``"in-frame"`` for a shipped sampler's name.

    Raises:
        ValueError: ``name`` is not shipped (the message lists the shipped names).
    """
    if name in ONE_SHOT_SAMPLERS:
        return ONE_SHOT
    if name in IN_FRAME_SAMPLERS:
        return IN_FRAME
    raise ValueError(f"unknown shipped sampler {name!r}; shipped: {', '.join(ONE_SHOT_SAMPLERS + IN_FRAME_SAMPLERS)}")


def shipped_file(name: str) -> Traversable:
    """The package resource ``agents/checkpoints/NAME.pt`` of a shipped sampler (it may be absent from
    an install that left out the package data: check ``.is_file()``).

    Raises:
        ValueError: ``name`` is not shipped.
    """
    sampler_kind(name)
    return importlib.resources.files(SHIPPED_PACKAGE).joinpath(SHIPPED_FOLDER, f"{name}.pt")
