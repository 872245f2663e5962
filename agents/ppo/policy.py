"""A permutation-equivariant actor-critic policy for stable-baselines3 (docs/algorithms.md, "Learned samplers").

SB3's :class:`~stable_baselines3.common.policies.ActorCriticPolicy` flattens
the observation and puts a dense layer over all action dimensions: that mixes
correspondences, ties the policy to one N and breaks permutation
equivariance. This policy keeps SB3's PPO machinery (rollouts, GAE, clipping,
logging, saving) but replaces the networks:

- features extractor: :class:`DictPassThrough` hands the ``{"features",
  "mask"}`` Dict on unflattened;
- actor (``action_net``): :class:`agents.network.CorrespondenceNet`; its
  per-correspondence logits, centred on the valid slots, are the means of a
  diagonal Gaussian with one learned log-std shared by every slot, so
  permuting the correspondences permutes the action distribution;
- critic (``value_net``): :class:`GlobalValueNet`, a small MLP over
  ``CorrespondenceNet.global_feature`` (masked mean and max of the
  embeddings), invariant to permutations; by default it has its own
  trunk (``share_trunk=False``), optionally the actor's.

The replacement happens in :meth:`EquivariantActorCriticPolicy._build` after
SB3's own ``_build``, which then **rebuilds** ``self.optimizer`` over the new
parameters (SB3 creates it inside ``_build``, over the networks it just made;
without the rebuild the new ones would never train). Log-probabilities and
entropies are summed over the *valid* slots only, so padding
(``max_correspondences > n_correspondences``) never enters the PPO ratio.

The deterministic action (the mean) equals
:meth:`agents.checkpoint.LearnedPolicy.act` of the same actor net on the
valid slots, so an exported actor (:func:`agents.ppo.train.export_actor`)
evaluates exactly as the SB3 model does.
"""

from __future__ import annotations

from typing import Any

import torch
from gymnasium import spaces
from stable_baselines3.common.distributions import DiagGaussianDistribution
from stable_baselines3.common.policies import ActorCriticPolicy
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from torch import nn

from agents.network import CorrespondenceNet

__all__ = ["DictPassThrough", "GlobalValueNet", "EquivariantActorCriticPolicy", "centred_logits"]

_FORCED = (
    "net_arch", "ortho_init", "features_extractor_class", "features_extractor_kwargs", "share_features_extractor",
    "use_sde",
)


class DictPassThrough(BaseFeaturesExtractor):
    """Hands the preprocessed ``{"features": (B, N, F), "mask": (B, N)}`` Dict on, unflattened.

    ``features_dim`` is nominal (SB3 requires one); nothing downstream reads it.
    """

    def __init__(self, observation_space: spaces.Dict) -> None:
        if not isinstance(observation_space, spaces.Dict) or set(observation_space.spaces) != {"features", "mask"}:
            raise ValueError(
                "DictPassThrough needs the vo_gym observation space Dict(features=Box(N, F), mask=MultiBinary(N)), "
                f"got {observation_space}"
            )
        super().__init__(observation_space, features_dim=1)

    def forward(self, observations: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:  # type: ignore[override]
        return observations


class GlobalValueNet(nn.Module):
    """State value from a permutation-invariant pooling of a trunk's embeddings."""

    def __init__(self, trunk: CorrespondenceNet, hidden: int = 64) -> None:
        super().__init__()
        self.trunk = trunk
        self.head = nn.Sequential(
            nn.Linear(2 * trunk.width, hidden), nn.ReLU(), nn.Linear(hidden, hidden), nn.ReLU(), nn.Linear(hidden, 1)
        )

    def forward(self, features: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        return self.head(self.trunk.global_feature(features, mask))


def centred_logits(logits: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Logits minus their mean over the valid slots (the guided env's softmax ignores a shift); 0 on padding."""
    valid = mask.to(logits.dtype)
    mean = (logits * valid).sum(-1, keepdim=True) / valid.sum(-1, keepdim=True).clamp_min(1.0)
    return torch.where(mask, logits - mean, torch.zeros_like(logits))


class EquivariantActorCriticPolicy(ActorCriticPolicy):
    """Actor-critic policy whose actor is a :class:`CorrespondenceNet` (see the module doc).

    Args (besides SB3's ``observation_space``, ``action_space``, ``lr_schedule``):
        width, blocks: the actor net's size (``CorrespondenceNet(n_features, width, blocks)``).
        critic_width, critic_blocks: the critic trunk's size (None: the actor's); ignored with ``share_trunk``.
        critic_hidden: hidden units of the critic's MLP over the pooled embeddings.
        share_trunk: the critic pools the actor net's own embeddings instead of a separate trunk's.
        log_std_init: initial value of the single log-std shared by every correspondence.
        train_config: a dict stored as is (and in the SB3 zip's ``policy_kwargs``), e.g. the
            training settings, so that a saved model carries its config.
        **kwargs: other :class:`ActorCriticPolicy` arguments (optimizer, ...); the network layout
            arguments (``net_arch``, ``ortho_init``, features extractor, gSDE) are fixed here.
    """

    def __init__(
        self,
        observation_space: spaces.Space,
        action_space: spaces.Space,
        lr_schedule,
        width: int = 64,
        blocks: int = 3,
        critic_width: int | None = None,
        critic_blocks: int | None = None,
        critic_hidden: int = 64,
        share_trunk: bool = False,
        log_std_init: float = 0.0,
        train_config: dict[str, Any] | None = None,
        **kwargs: Any,
    ) -> None:
        if kwargs.pop("use_sde", False):  # on-policy algorithms always pass it
            raise ValueError("EquivariantActorCriticPolicy does not support gSDE (use_sde=True)")
        forced = sorted(k for k in _FORCED if k in kwargs)
        if forced:
            raise ValueError(f"EquivariantActorCriticPolicy fixes {forced} itself; do not pass them")
        if not isinstance(action_space, spaces.Box) or len(action_space.shape) != 1:
            raise ValueError(f"EquivariantActorCriticPolicy needs a 1-D Box action space, got {action_space}")
        features = observation_space["features"] if isinstance(observation_space, spaces.Dict) else None
        if features is None or len(features.shape) != 2 or features.shape[0] != action_space.shape[0]:
            raise ValueError(
                "EquivariantActorCriticPolicy needs Dict(features=Box(N, F), mask=MultiBinary(N)) observations and "
                f"one action per correspondence slot, got {observation_space} and {action_space}"
            )
        self.n_features = int(features.shape[1])
        self.width, self.blocks = int(width), int(blocks)
        self.critic_width = int(critic_width if critic_width is not None else width)
        self.critic_blocks = int(critic_blocks if critic_blocks is not None else blocks)
        self.critic_hidden = int(critic_hidden)
        self.share_trunk = bool(share_trunk)
        self.train_config = dict(train_config or {})
        super().__init__(
            observation_space, action_space, lr_schedule, net_arch=[], ortho_init=False, log_std_init=log_std_init,
            features_extractor_class=DictPassThrough, share_features_extractor=True, use_sde=False, **kwargs,
        )

    # ------------------------------------------------------------------ construction

    def _build(self, lr_schedule) -> None:
        # SB3 builds an (empty) MLP extractor, a dense Linear(latent, N) action net over all slots,
        # a per-dimension log-std, a Linear value net and the optimizer over them.
        super()._build(lr_schedule)
        assert isinstance(self.action_dist, DiagGaussianDistribution)
        # Replace them: the dense action net would mix correspondences.
        self.action_net = CorrespondenceNet(self.n_features, self.width, self.blocks)
        trunk = self.action_net if self.share_trunk else CorrespondenceNet(
            self.n_features, self.critic_width, self.critic_blocks
        )
        self.value_net = GlobalValueNet(trunk, self.critic_hidden)
        self.log_std = nn.Parameter(torch.full((1,), float(self.log_std_init)), requires_grad=True)
        self.to(self.device)
        # ... and rebuild the optimizer, or the new parameters never train.
        self.optimizer = self.optimizer_class(self.parameters(), lr=lr_schedule(1), **self.optimizer_kwargs)

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()
        for key in _FORCED:
            data.pop(key, None)
        data.update(
            width=self.width, blocks=self.blocks, critic_width=self.critic_width, critic_blocks=self.critic_blocks,
            critic_hidden=self.critic_hidden, share_trunk=self.share_trunk, train_config=self.train_config,
        )
        for key in ("squash_output", "full_std", "use_expln"):  # gSDE-only settings
            data.pop(key, None)
        return data

    # ------------------------------------------------------------------ networks

    def _inputs(self, obs) -> tuple[torch.Tensor, torch.Tensor]:
        x = self.extract_features(obs)
        return x["features"].float(), x["mask"] > 0.5

    def action_mean(self, features: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        """Gaussian means ``(B, N)``: the actor's logits centred on the valid slots (0 on padding)."""
        return centred_logits(self.action_net(features, mask), mask)

    def _distribution(self, features: torch.Tensor, mask: torch.Tensor) -> DiagGaussianDistribution:
        return self.action_dist.proba_distribution(self.action_mean(features, mask), self.log_std)

    @staticmethod
    def _masked_sum(values: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        return (values * mask.to(values.dtype)).sum(dim=-1)

    def forward(self, obs, deterministic: bool = False):
        features, mask = self._inputs(obs)
        dist = self._distribution(features, mask)
        actions = dist.get_actions(deterministic=deterministic)
        log_prob = self._masked_sum(dist.distribution.log_prob(actions), mask)
        values = self.value_net(features, mask)
        return actions.reshape((-1, *self.action_space.shape)), values, log_prob

    def evaluate_actions(self, obs, actions: torch.Tensor):
        features, mask = self._inputs(obs)
        dist = self._distribution(features, mask)
        log_prob = self._masked_sum(dist.distribution.log_prob(actions), mask)
        entropy = self._masked_sum(dist.distribution.entropy(), mask)
        return self.value_net(features, mask), log_prob, entropy

    def get_distribution(self, obs) -> DiagGaussianDistribution:
        return self._distribution(*self._inputs(obs))

    def predict_values(self, obs) -> torch.Tensor:
        return self.value_net(*self._inputs(obs))
