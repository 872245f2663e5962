"""PPO (stable-baselines3) on ``vo_gym/StereoVO-v0`` with the permutation-equivariant policy.

- :mod:`agents.ppo.config`: :class:`~agents.ppo.config.PPOConfig`, the vectorised training env and
  the SB3 model built from a config;
- :mod:`agents.ppo.policy`: ``EquivariantActorCriticPolicy``, the SB3 policy (actor = the
  correspondence network, critic pooled over the matches);
- :mod:`agents.ppo.archive`: reading an SB3 zip back without unpickling anything in it;
- :mod:`agents.ppo.train`: :func:`~agents.ppo.train.train_ppo`, held-out evaluation, checkpoints,
  and the actor's export as a sampler checkpoint.

Import each name from the module that defines it; this package re-exports nothing.
"""
