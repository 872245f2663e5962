"""The learned in-frame sampler as a policy of the adaptive environment.

:class:`AdaptiveSamplerPolicy`: the logits of :class:`~agents.adaptive.network.AdaptiveSamplerNet`
as they are, stop once the stop belief reaches ``confidence``.
"""

from __future__ import annotations

import numpy as np
import torch

from agents.adaptive.network import AdaptiveSamplerNet, make_action, observation_tensors
from agents.checkpoint import IN_FRAME


class AdaptiveSamplerPolicy:
    """The learned in-frame sampler as a policy of the adaptive env: ``act(obs, info) -> action``.

    ``obs`` is the adaptive observation (:meth:`vo_gym.in_frame.InFrameSearch.observation`); the action
    is the next batch's logits and the stop slot, stop once the stop belief reaches ``confidence``.
    """

    kind = IN_FRAME

    def __init__(self, net: AdaptiveSamplerNet, confidence: float = 0.9, name: str = "adaptive") -> None:
        if not 0 < confidence < 1:
            raise ValueError(f"confidence must be in (0, 1), got {confidence!r}")
        self.net, self.confidence, self.name = net.eval(), float(confidence), name
        self.last_stop_belief = 0.0

    def reset(self) -> None:
        self.last_stop_belief = 0.0

    @torch.no_grad()
    def act(self, obs: dict, info: dict | None = None) -> np.ndarray:
        """The action ``(M + 1,)`` float32 (:func:`~agents.adaptive.network.make_action`) for the adaptive observation ``obs``.

        Raises:
            ValueError: ``obs`` is not the adaptive observation dict (``features``, ``mask``, ``globals``).
        """
        if not isinstance(obs, dict) or not {"features", "mask", "globals"} <= set(obs):
            got = sorted(obs) if isinstance(obs, dict) else type(obs).__name__
            raise ValueError(f"{self.name}: an in-frame sampler acts on the adaptive observation "
                             f"{{'features', 'mask', 'globals'}} of a running search, got {got}; "
                             "on raw matches use agents.LearnedEstimator")
        width = np.shape(obs["features"])[-1]
        if width != self.net.n_features:
            raise ValueError(f"{self.name}: expected {self.net.n_features} adaptive features per correspondence, got {width}")
        logits, stop = self.net(*observation_tensors(obs))
        self.last_stop_belief = float(torch.sigmoid(stop)[0])
        return make_action(logits[0].numpy(), obs["mask"], self.last_stop_belief >= self.confidence)
