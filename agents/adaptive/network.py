"""The network of the learned in-frame sampler, and the action it makes in the adaptive environment.

:class:`AdaptiveSamplerNet`: the project's permutation-equivariant correspondence network
(:class:`agents.network.CorrespondenceNet`, shared MLP with context normalisation) over each
correspondence's adaptive features with the global loop state appended to every row, so that the
same weights serve any number of matches and a permutation of the rows permutes the logits. Two heads:

- per-correspondence logits: the next batch's sampling logits, which are also the weights by which
  the frame's final hypothesis is selected (belief-weighted support);
- a stop logit from the masked mean and max of the embeddings and the globals: ``sigmoid`` of it is
  the network's belief that the hypothesis the frame would end on now is right.

With ``prior`` (a shipped one-shot sampler, e.g. ``"ngransac-supervised"``), the network carries
a frozen copy of that sampler's network and its per-correspondence logits are the one-shot logits
(centred on the valid rows) plus its own, whose last layer starts at zero: training begins from the
one-shot sampler and learns what the loop's evidence adds, how to select and when to stop (ARS-MAGSAC
likewise starts from network priors and updates them in the frame). The copy travels in the
checkpoint, so loading never needs the shipped file.

:func:`observation_tensors` turns an adaptive observation into the network's inputs (a batch of
one); :func:`make_action` turns logits and a stop decision into the env's action.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from agents.checkpoint import shipped_checkpoint
from agents.network import PAD_LOGIT, CorrespondenceNet, correspondence_net_shapes
from agents.network_size import correspondence_net_parameters
from vo_gym.adaptive_env import ADAPTIVE_FEATURE_NAMES, GLOBAL_FEATURE_NAMES

LOGIT_BOUND = 10.0
STOP_ACTION = 1.0


class AdaptiveSamplerNet(nn.Module):
    """Per-correspondence logits ``(B, N)`` and a stop logit ``(B,)`` from the adaptive observation.

    Inputs: ``features (B, N, F)``, ``mask (B, N)`` bool, ``globals (B, G)``.
    """

    def __init__(self, n_features: int = len(ADAPTIVE_FEATURE_NAMES), n_globals: int = len(GLOBAL_FEATURE_NAMES),
                 width: int = 48, blocks: int = 3, prior: dict[str, int] | None = None) -> None:
        super().__init__()
        self.n_features, self.n_globals, self.width, self.blocks = n_features, n_globals, width, blocks
        self.body = CorrespondenceNet(n_features + n_globals, width, blocks)
        self.stop = nn.Sequential(nn.Linear(2 * width + n_globals, width), nn.ReLU(), nn.Linear(width, 1))
        self.prior: CorrespondenceNet | None = None
        if prior is not None:  # the one-shot network's architecture; its weights come from a checkpoint
            if prior["n_features"] > n_features:
                raise ValueError(f"prior network reads {prior['n_features']} features, the observation has {n_features}")
            self.prior = CorrespondenceNet(**prior).requires_grad_(False)
            nn.init.zeros_(self.body.head.weight)
            nn.init.zeros_(self.body.head.bias)

    @classmethod
    def with_prior(cls, sampler: str, width: int = 48, blocks: int = 3) -> "AdaptiveSamplerNet":
        """A fresh network over the one-shot ``sampler``: a shipped name (``agents.checkpoint.SHIPPED_SAMPLERS``)
        or a one-shot ``.pt`` file of :func:`agents.checkpoint.save_checkpoint`."""
        from agents.checkpoint import SHIPPED_SAMPLERS, load_checkpoint

        if sampler in SHIPPED_SAMPLERS:
            with shipped_checkpoint(sampler) as path:
                one_shot, _ = load_checkpoint(path)
        else:
            one_shot, _ = load_checkpoint(Path(sampler).expanduser())
        net = cls(width=width, blocks=blocks, prior=one_shot.config())
        net.prior.load_state_dict(one_shot.state_dict())
        return net

    def config(self) -> dict[str, Any]:
        return {"n_features": self.n_features, "n_globals": self.n_globals, "width": self.width, "blocks": self.blocks,
                "prior": None if self.prior is None else self.prior.config()}

    @staticmethod
    def parameter_shapes(n_features: int, n_globals: int, width: int, blocks: int,
                         prior: dict[str, int] | None = None) -> dict[str, tuple[int, ...]]:
        """The state dict's parameter shapes of ``AdaptiveSamplerNet(...)`` by name, from the sizes
        alone (nothing is allocated); :func:`parameter_count` is their total."""
        shapes = correspondence_net_shapes(n_features + n_globals, width, blocks, prefix="body.")
        shapes.update({"stop.0.weight": (width, 2 * width + n_globals), "stop.0.bias": (width,),
                       "stop.2.weight": (1, width), "stop.2.bias": (1,)})
        if prior is not None:
            shapes.update(correspondence_net_shapes(prior["n_features"], prior["width"], prior["blocks"], prefix="prior."))
        return shapes

    @staticmethod
    def parameter_count(n_features: int, n_globals: int, width: int, blocks: int,
                        prior: dict[str, int] | None = None) -> int:
        """The number of parameters of ``AdaptiveSamplerNet(...)``, by arithmetic (nothing is allocated)."""
        count = correspondence_net_parameters(n_features + n_globals, width, blocks)
        count += width * (2 * width + n_globals) + width + width + 1
        if prior is not None:
            count += correspondence_net_parameters(prior["n_features"], prior["width"], prior["blocks"])
        return count

    def forward(self, features: torch.Tensor, mask: torch.Tensor, globals_: torch.Tensor):
        mask = mask.bool()
        rows = torch.cat([features, globals_.unsqueeze(1).expand(-1, features.shape[1], -1)], dim=-1)
        embedded = self.body.embed(rows, mask)
        logits = self.body.head(embedded).squeeze(-1)
        if self.prior is not None:
            with torch.no_grad():
                one_shot = self.prior.head(self.prior.embed(features[..., :self.prior.n_features], mask)).squeeze(-1)
                valid = mask.float()
                one_shot = one_shot - (one_shot * valid).sum(-1, keepdim=True) / valid.sum(-1, keepdim=True).clamp_min(1)
            logits = logits + one_shot
        logits = logits.masked_fill(~mask, PAD_LOGIT)
        m = mask.unsqueeze(-1)
        mean = embedded.sum(dim=1) / m.sum(dim=1).clamp_min(1)
        peak = embedded.masked_fill(~m, float("-inf")).amax(dim=1).clamp_min(0.0)
        stop = self.stop(torch.cat([mean, peak, globals_], dim=-1)).squeeze(-1)
        return logits, stop


def observation_tensors(obs: dict) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The adaptive observation ``obs`` as the network's inputs, a batch of one: ``features (1, N, F)``,
    ``mask (1, N)`` bool, ``globals (1, G)``."""
    return (torch.as_tensor(obs["features"], dtype=torch.float32).unsqueeze(0),
            torch.as_tensor(obs["mask"]).bool().unsqueeze(0),
            torch.as_tensor(obs["globals"], dtype=torch.float32).unsqueeze(0))


def make_action(logits: np.ndarray, mask: np.ndarray, stop: bool) -> np.ndarray:
    """The env's action ``(M + 1,)`` float32: clipped logits on valid slots, the stop slot +-1."""
    out = np.where(np.asarray(mask, bool), np.clip(logits, -LOGIT_BOUND, LOGIT_BOUND), -LOGIT_BOUND)
    return np.concatenate([out, [STOP_ACTION if stop else -STOP_ACTION]]).astype(np.float32)
