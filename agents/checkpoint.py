"""Checkpoints of learned samplers: weights plus the config and feature layout they need.

A checkpoint from another feature layout is refused with a clear message,
because a network fed columns in a different meaning would still run and
silently sample nonsense.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import torch

from agents.network import CorrespondenceNet
from vo_gym.features import FEATURE_LAYOUT_VERSION, FEATURE_NAMES, check_feature_layout

FORMAT_VERSION = 1


def save_checkpoint(path: str | Path, net: CorrespondenceNet, config: dict[str, Any], state: dict[str, Any] | None = None) -> Path:
    """Write ``net`` with its architecture, the training ``config`` and optional trainer ``state``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    payload = {
        "format_version": FORMAT_VERSION,
        "network": net.config(),
        "state_dict": {k: v.detach().cpu() for k, v in net.state_dict().items()},
        "feature_names": list(FEATURE_NAMES),
        "feature_layout_version": FEATURE_LAYOUT_VERSION,
        "config": config,
        "trainer_state": state or {},
    }
    tmp = path.with_suffix(path.suffix + ".tmp")
    torch.save(payload, tmp)
    tmp.replace(path)  # never leave a half-written checkpoint behind
    return path


def load_checkpoint(path: str | Path) -> tuple[CorrespondenceNet, dict[str, Any]]:
    """Load a checkpoint; returns the network (eval mode) and the whole payload.

    Raises:
        FileNotFoundError: no such file.
        ValueError: not a vo-gym checkpoint, or its feature layout differs from this version's.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no checkpoint at {path}")
    payload = torch.load(path, map_location="cpu", weights_only=False)
    if not isinstance(payload, dict) or "feature_names" not in payload or "network" not in payload:
        raise ValueError(f"{path} is not a vo-gym sampler checkpoint")
    try:
        check_feature_layout(payload["feature_names"], payload["feature_layout_version"])
    except ValueError as err:
        raise ValueError(f"checkpoint {path} was trained on another feature layout: {err}") from None
    net = CorrespondenceNet(**payload["network"])
    net.load_state_dict(payload["state_dict"])
    net.eval()
    return net, payload


class LearnedPolicy:
    """A trained network as a policy: observation ``{"features", "mask"}`` in, logits out."""

    def __init__(self, net: CorrespondenceNet, name: str = "learned", temperature: float = 1.0) -> None:
        self.net = net.eval()
        self.name = name
        self.temperature = temperature

    @classmethod
    def from_checkpoint(cls, path: str | Path, name: str | None = None) -> "LearnedPolicy":
        net, _ = load_checkpoint(path)
        return cls(net, name or Path(path).stem)

    @torch.no_grad()
    def act(self, observation: dict) -> np.ndarray:
        features = torch.as_tensor(np.asarray(observation["features"], dtype=np.float32))
        mask = torch.as_tensor(np.asarray(observation["mask"]).astype(bool))
        single = features.ndim == 2
        if single:
            features, mask = features[None], mask[None]
        logits = self.net(features, mask) / self.temperature
        # Centre on the valid slots so the action stays inside the env's bounded Box.
        valid = mask.float()
        mean = (logits * valid).sum(-1, keepdim=True) / valid.sum(-1, keepdim=True).clamp_min(1)
        from agents.policies import LOGIT_BOUND

        out = torch.where(mask, (logits - mean).clamp(-LOGIT_BOUND, LOGIT_BOUND), torch.tensor(-LOGIT_BOUND))
        out = out.numpy().astype(np.float32)
        return out[0] if single else out


def export_checkpoint(source: str | Path, destination: str | Path) -> Path:
    """Copy a checkpoint without its optimizer state: what ships needs weights, config and layout only."""
    net, payload = load_checkpoint(source)
    history = payload.get("trainer_state", {}).get("history", [])
    return save_checkpoint(destination, net, payload["config"], {"history": history})
