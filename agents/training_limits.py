"""The caps on the trainers' counts (torch-free), beside the network caps of :mod:`agents.network_size`.

A trainer config (:class:`agents.ngransac.NGRansacConfig`, :class:`agents.ppo.config.PPOConfig`,
:class:`agents.adaptive.train.AdaptiveTrainConfig`) refuses a count past its cap, naming the field
and the value, before anything runs: such a count is a typo, and one as large as ``10**400`` once
overflowed a float only once a sweep had started (its number of reports). The counts the simulator,
the environment or the estimator take keep their own caps
(:data:`stereovo.simulation.config.MAX_FRAMES`, :data:`~stereovo.simulation.config.MAX_CORRESPONDENCES`,
:data:`stereovo.estimation.estimator_options.MAX_COUNT`).
"""

from __future__ import annotations

MAX_TRAINING_STEPS = 10**9
"""The most training steps a trainer config takes (NG-RANSAC frames, PPO environment steps, in-frame
episodes), and the cap on its periods and evaluation lengths (frames or steps between evaluations and
checkpoints, evaluation frames, rollout steps, epochs). NG-RANSAC trains some 30 frames a second on
one core and PPO some 100 environment steps, so a billion is months to years of training."""

MAX_ENVS = 1024
"""The most environments PPO steps in parallel (``n_envs``; each one a process with ``vec_env="subproc"``)."""
