"""``load_sampler`` for both kinds of learned sampler, by shipped name or checkpoint path.

One-shot samplers (:data:`agents.checkpoint.SHIPPED_SAMPLERS`) set a frame's priors once:
:class:`agents.checkpoint.LearnedPolicy`. In-frame samplers
(:data:`agents.checkpoint.SHIPPED_IN_FRAME_SAMPLERS`) steer the search batch by batch and stop it:
:class:`agents.adaptive.policy.AdaptiveSamplerPolicy`. Both policies carry ``name`` and ``kind``; this
module sits above both formats' modules so that neither imports the other.
"""

from __future__ import annotations

import os

from agents.adaptive.checkpoint import load_adaptive
from agents.adaptive.policy import AdaptiveSamplerPolicy
from agents.checkpoint import (
    IN_FRAME,
    ONE_SHOT,
    SAMPLER_KINDS,
    LearnedPolicy,
    resolve_sampler,
    resolved_policy,
)

__all__ = ["load_sampler"]


def load_sampler(name_or_path: str | os.PathLike, temperature: float = 1.0, kind: str | None = None,
                 confidence: float = 0.9) -> LearnedPolicy | AdaptiveSamplerPolicy:
    """A learned sampler of either kind as a policy.

    Args:
        name_or_path: a shipped name or a ``.pt`` file of either format.
        temperature: a one-shot sampler's logits are divided by it.
        kind: None takes either kind; ``"one-shot"`` or ``"in-frame"`` refuses the other.
        confidence: the stop belief at which an in-frame sampler stops, in (0, 1).

    Raises:
        ValueError: an unknown name or kind, a sampler of another kind than ``kind``;
        CheckpointError (a ValueError): an unusable file; FileNotFoundError: no such file.
    """
    if kind is not None and kind not in SAMPLER_KINDS:
        raise ValueError(f"kind must be None or one of {', '.join(SAMPLER_KINDS)}, got {kind!r}")
    found, name, path = resolve_sampler(name_or_path)
    if kind is not None and found != kind:
        raise ValueError(f"sampler {os.fspath(name_or_path)!r} is an {found} sampler, not {kind}")
    if found == IN_FRAME:
        net, _ = load_adaptive(name if path is None else path)
        return AdaptiveSamplerPolicy(net, confidence=confidence, name=name)
    return resolved_policy(name, path, temperature)
