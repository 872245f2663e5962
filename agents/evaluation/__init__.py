"""``vo-gym evaluate``'s protocol: learned samplers, heuristics and classical methods on the same frames.

- :mod:`agents.evaluation.setup`: the agents (names, checkpoints), the settings, the classical
  rows' recipes and the per-frame row format;
- :mod:`agents.evaluation.run`: the one-shot protocol (:func:`~agents.evaluation.run.run_evaluation`);
- :mod:`agents.evaluation.report`: the summary, the markdown tables, the figures and the files;
- :mod:`agents.evaluation.in_frame`: the in-frame (adaptive) comparison, samplers that act inside
  one frame's RANSAC loop (``vo-gym evaluate --adaptive``).

Import each name from the module that defines it; this package re-exports nothing.
"""
