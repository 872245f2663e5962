"""The caps on the trainers' counts and learning rate (torch-free), beside the network caps of
:mod:`agents.network_size`.

A trainer config (:class:`agents.ngransac.NGRansacConfig`, :class:`agents.ppo.config.PPOConfig`,
:class:`agents.adaptive.train.AdaptiveTrainConfig`) refuses a count past its cap, naming the field
and the value, before anything runs: such a count is a typo, and one as large as ``10**400`` once
overflowed a float only once a sweep had started (its number of reports). The counts the simulator,
the environment or the estimator take keep their own caps
(:data:`stereovo.simulation.config.MAX_FRAMES`, :data:`~stereovo.simulation.config.MAX_CORRESPONDENCES`,
:data:`stereovo.estimation.estimator_options.MAX_COUNT`). A learning rate is refused from
:data:`MAX_LEARNING_RATE` up, where training no longer trains.
"""

from __future__ import annotations

from stereovo.options import Number

MAX_TRAINING_STEPS = 10**9
"""The most training steps a trainer config takes (NG-RANSAC frames, PPO environment steps, in-frame
episodes), and the cap on its periods and evaluation lengths (frames or steps between evaluations and
checkpoints, evaluation frames, rollout steps, epochs). NG-RANSAC trains some 30 frames a second on
one core and PPO some 100 environment steps, so a billion is months to years of training."""

MAX_ENVS = 1024
"""The most environments PPO steps in parallel (``n_envs``; each one a process with ``vec_env="subproc"``)."""

MAX_LEARNING_RATE = 0.1
"""The trainers' learning rates must be below this (``0 < lr < 0.1``). All three trainers step with Adam,
which moves every weight by about the learning rate at each step, whatever the gradient's size, and
their networks start with weights of about 0.1 to 0.3 (``1/sqrt(fan in)`` at 10 to 64 inputs): at 0.1
one step is as large as the weights themselves and training is noise. Measured with ``vo-gym train``
(NG-RANSAC, seed 0): 0.01 and 0.03 trained (held-out success 1.0 and 0.95 after 1000 frames), 0.1
collapsed the sampling weights onto fewer than three points by frame 300 (a traceback), and 1e30
turned PPO's logits to NaN in its first update. The project's runs use 3e-5 to 1e-3."""

LEARNING_RATE = Number(low=0.0, high=MAX_LEARNING_RATE, low_open=True, high_open=True)
"""The declaration of a trainer config's learning rate (:mod:`stereovo.options`): finite, in ``(0, 0.1)``."""
