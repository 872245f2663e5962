"""The learned in-frame sampler of :class:`vo_gym.adaptive_env.StereoVOAdaptiveEnv` and its trainer.

- :mod:`agents.adaptive.network`: :class:`~agents.adaptive.network.AdaptiveSamplerNet` (logits for
  the next batch and a stop belief, optionally over a frozen one-shot prior) and the env's action
  (:func:`~agents.adaptive.network.make_action`);
- :mod:`agents.adaptive.policy`: :class:`~agents.adaptive.policy.AdaptiveSamplerPolicy`, the
  network as a policy of the adaptive env, stopping once its stop belief reaches a confidence;
- :mod:`agents.adaptive.checkpoint`: :func:`~agents.adaptive.checkpoint.save_adaptive`,
  :func:`~agents.adaptive.checkpoint.load_adaptive` (by path or shipped name, checked before any
  network is built);
- :mod:`agents.adaptive.train`: :func:`~agents.adaptive.train.train_in_frame` (policy gradient with
  two supervised auxiliary losses) and the command line of ``python -m agents.adaptive``
  (:mod:`agents.adaptive.__main__`).

Import each name from the module that defines it; this package re-exports nothing.
"""
