"""A permutation-equivariant per-correspondence network (PointNet / context normalisation).

Each correspondence's feature row goes through a shared MLP; after every
layer the activations are normalised over the *valid* correspondences of the
frame (context normalisation, Yi et al. 2018, as in NG-RANSAC), which is how
global context enters without breaking equivariance. Padded slots never
influence valid ones, so the same weights serve any number of matches.

Shapes: features ``(B, N, F)`` float32, mask ``(B, N)`` bool (True = valid),
logits ``(B, N)``; padded slots get ``PAD_LOGIT``.
"""

from __future__ import annotations

import torch
from torch import nn

PAD_LOGIT = -1e4  # softmax weight ~0 for padded slots without producing NaN


def masked_context_norm(x: torch.Tensor, mask: torch.Tensor, eps: float = 1e-5) -> torch.Tensor:
    """Normalise ``x (B, N, C)`` per frame and channel over the valid slots ``mask (B, N)``."""
    m = mask.unsqueeze(-1).to(x.dtype)
    count = m.sum(dim=1, keepdim=True).clamp_min(1.0)
    mean = (x * m).sum(dim=1, keepdim=True) / count
    var = (((x - mean) * m) ** 2).sum(dim=1, keepdim=True) / count
    return (x - mean) / torch.sqrt(var + eps) * m


class ResidualContextBlock(nn.Module):
    """Two shared linear layers with context normalisation and a skip connection."""

    def __init__(self, width: int) -> None:
        super().__init__()
        self.fc1 = nn.Linear(width, width)
        self.fc2 = nn.Linear(width, width)

    def forward(self, x: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        h = torch.relu(masked_context_norm(self.fc1(x), mask))
        h = masked_context_norm(self.fc2(h), mask)
        return torch.relu(x + h)


class CorrespondenceNet(nn.Module):
    """Per-correspondence logits from per-correspondence features.

    Args:
        n_features: F, the feature row length (``vo_gym.features.N_FEATURES``).
        width: hidden channels.
        blocks: residual context blocks.
    """

    def __init__(self, n_features: int, width: int = 64, blocks: int = 3) -> None:
        super().__init__()
        self.n_features = n_features
        self.width = width
        self.blocks_count = blocks
        self.input = nn.Linear(n_features, width)
        self.blocks = nn.ModuleList(ResidualContextBlock(width) for _ in range(blocks))
        self.head = nn.Linear(width, 1)

    def config(self) -> dict:
        return {"n_features": self.n_features, "width": self.width, "blocks": self.blocks_count}

    def embed(self, features: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        """Per-correspondence embeddings ``(B, N, width)``; padded rows are zero."""
        if features.shape[-1] != self.n_features:
            raise ValueError(f"expected {self.n_features} features per correspondence, got {features.shape[-1]}")
        mask = mask.bool()
        x = torch.relu(masked_context_norm(self.input(features), mask))
        for block in self.blocks:
            x = block(x, mask)
        return x * mask.unsqueeze(-1)

    def forward(self, features: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        logits = self.head(self.embed(features, mask)).squeeze(-1)
        return logits.masked_fill(~mask.bool(), PAD_LOGIT)

    def global_feature(self, features: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        """Masked mean and max of the embeddings ``(B, 2 * width)``: the critic's input."""
        x = self.embed(features, mask)
        m = mask.bool().unsqueeze(-1)
        mean = x.sum(dim=1) / m.sum(dim=1).clamp_min(1)
        peak = x.masked_fill(~m, float("-inf")).amax(dim=1).clamp_min(0.0)
        return torch.cat([mean, peak], dim=-1)


def correspondence_net_shapes(n_features: int, width: int, blocks: int, prefix: str = "") -> dict[str, tuple[int, ...]]:
    """The state dict's parameter shapes of ``CorrespondenceNet(n_features, width, blocks)``, by name
    (each prefixed with ``prefix``), computed from the sizes alone: nothing is allocated."""
    shapes = {f"{prefix}input.weight": (width, n_features), f"{prefix}input.bias": (width,)}
    for i in range(blocks):
        for layer in ("fc1", "fc2"):
            shapes[f"{prefix}blocks.{i}.{layer}.weight"] = (width, width)
            shapes[f"{prefix}blocks.{i}.{layer}.bias"] = (width,)
    shapes.update({f"{prefix}head.weight": (1, width), f"{prefix}head.bias": (1,)})
    return shapes
