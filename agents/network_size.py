"""How large a sampler's networks are and may be, by arithmetic (torch-free).

The caps every checkpoint loader and every trainer's config apply, and the parameter counts they
check against them, computed from the declared sizes so that nothing is allocated first: a file or
a config declaring a huge network is refused from its numbers alone. Kept apart from
:mod:`agents.network` so that configs (:class:`agents.ppo.config.PPOConfig`) check their sizes
without importing torch.
"""

from __future__ import annotations

MAX_NETWORK_SIZE = 4096
"""The largest size (features, width, blocks) a checkpoint's network may declare, each on its own."""
MAX_NETWORK_PARAMETERS = 2 ** 24
"""The most parameters a checkpoint's networks may declare, all together: 16,777,216 (64 MiB of
float32). The shipped samplers hold 6,849 (``ppo``) to 33,411 (``adaptive-pg-prior``), about 500
times fewer, and the cap still admits e.g. width 1024 with 7 blocks; a file declaring more is refused
before any network is built (its sizes alone would otherwise allocate up to hundreds of GB)."""


def correspondence_net_parameters(n_features: int, width: int, blocks: int) -> int:
    """The number of parameters of ``CorrespondenceNet(n_features, width, blocks)`` (the sum over
    :func:`agents.network.correspondence_net_shapes`)."""
    return width * (n_features + 1) + blocks * 2 * width * (width + 1) + width + 1


def ppo_policy_parameters(n_features: int, width: int, blocks: int, critic_width: int, critic_hidden: int,
                          share_trunk: bool) -> int:
    """The number of parameters of the PPO policy (:mod:`agents.ppo.policy`): the actor's
    correspondence net, the critic's trunk (``critic_width`` wide, ``blocks`` deep; with
    ``share_trunk`` none, and ``critic_width`` must then be ``width``), the critic's MLP over the
    trunk's pooled embeddings (``2 critic_width -> critic_hidden -> critic_hidden -> 1``) and the
    one log-std."""
    count = correspondence_net_parameters(n_features, width, blocks)
    if not share_trunk:
        count += correspondence_net_parameters(n_features, critic_width, blocks)
    return count + 2 * critic_width * critic_hidden + critic_hidden + critic_hidden * critic_hidden + 2 * critic_hidden + 2
