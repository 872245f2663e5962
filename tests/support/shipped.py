"""The setting in which the shipped samplers are held to their margin over uniform sampling: eps 0.8,
16 hypotheses per frame, N = 500 (the README's headline setting), three fixed 10-frame episodes."""

SEEDS = (0, 1, 2)
SETTING = dict(outlier_ratio=0.8, budget=16, n_frames=10, n_correspondences=500)
MARGIN = 0.4  # success-rate points a shipped sampler gains over uniform sampling, at least
