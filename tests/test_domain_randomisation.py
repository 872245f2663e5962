"""Domain randomisation of the one-shot trainer: each sequence draws its own match-error process."""

from __future__ import annotations

import itertools

import numpy as np

from agents.ngransac import RANDOMISED_AUC, NGRansacConfig, NGRansacTrainer, randomised_frame_stream


def first_frames(seed: int, sequences: int = 6):
    stream = randomised_frame_stream(NGRansacConfig(domain_randomisation=True, frames_per_sequence=2), seed)
    return list(itertools.islice(stream, 0, 2 * sequences, 2))


def test_each_sequence_draws_its_own_process_and_the_seed_fixes_them():
    frames = first_frames(0)
    aucs = [f.score_auc for f in frames]
    assert len(set(aucs)) == len(aucs) and all(RANDOMISED_AUC[0] <= a <= RANDOMISED_AUC[1] for a in aucs)
    again = first_frames(0)
    for a, b in zip(frames, again):
        np.testing.assert_array_equal(a.prev, b.prev)
        assert a.score_auc == b.score_auc
    assert [f.score_auc for f in first_frames(1)] != aucs


def test_the_trainer_runs_on_the_randomised_stream():
    config = NGRansacConfig(domain_randomisation=True, frames=3, eval_every=3, eval_frames=2, n_correspondences=80,
                            frames_per_sequence=2, pools=2, budget=4)
    trainer = NGRansacTrainer(config)
    trainer.train()
    assert trainer.step == 3 and len(trainer.history) == 1
