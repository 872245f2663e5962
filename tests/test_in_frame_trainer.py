"""agents.adaptive.train_in_frame: the in-frame sampler's trainer as a library call with a time budget."""

from __future__ import annotations

import json

import pytest
import torch

from agents import LearnedEstimator
from agents.adaptive import AdaptiveTrainConfig, load_adaptive, train_in_frame
from stereovo.simulation import SimulationConfig, simulate_frame


def tiny(**kw) -> AdaptiveTrainConfig:
    return AdaptiveTrainConfig(minutes=10.0, frames_per_episode=2, n=60, max_hypotheses=8, log_every_s=0.0, **kw)


def test_a_short_run_writes_a_loadable_checkpoint_and_its_log(tmp_path):
    threads = torch.get_num_threads()
    try:
        result = train_in_frame(tiny(max_episodes=2, seed=3), tmp_path / "run", progress=False)
    finally:
        torch.set_num_threads(threads)
    assert result.episodes == 2 and result.frames == 4
    assert result.checkpoint == tmp_path / "run" / "adaptive.pt"
    net, payload = load_adaptive(result.checkpoint)
    assert payload["config"]["max_episodes"] == 2 and payload["config"]["seed"] == 3
    lines = (tmp_path / "run" / "training.jsonl").read_text().splitlines()
    assert len(lines) == 2 and json.loads(lines[-1])["episodes"] == 2  # one log window per episode here
    summary = json.loads((tmp_path / "run" / "training.json").read_text())
    assert summary["algo"] == "adaptive" and summary["episodes"] == 2 and summary["frames"] == 4
    # what it wrote runs through the public estimator
    frame = simulate_frame(SimulationConfig(n_correspondences=60, outlier_ratio=0.3), rng=1)
    est = LearnedEstimator(result.checkpoint, budget=8).estimate(frame.prev, frame.curr, frame.camera, frame.scores)
    assert est.sampler == "adaptive" and est.n_hypotheses == 8


def test_the_same_seed_trains_the_same_weights(tmp_path):
    threads = torch.get_num_threads()
    try:
        a = train_in_frame(tiny(max_episodes=1, seed=5), tmp_path / "a", progress=False)
        b = train_in_frame(tiny(max_episodes=1, seed=5), tmp_path / "b", progress=False)
    finally:
        torch.set_num_threads(threads)
    wa, wb = load_adaptive(a.checkpoint)[0].state_dict(), load_adaptive(b.checkpoint)[0].state_dict()
    assert all(torch.equal(wa[k], wb[k]) for k in wa)
    assert any(not torch.equal(wa[k], torch.zeros_like(wa[k])) for k in wa)


@pytest.mark.parametrize("kw, match", [
    ({"minutes": 0}, "minutes"), ({"minutes": float("nan")}, "minutes"), ({"clock": "gpu"}, "clock"),
    ({"max_episodes": 0}, "max_episodes"), ({"epsilons": (0.9, 0.5)}, "epsilons"), ({"n": 0}, "n must"),
    ({"prior": "ngransac-supervised", "init": "adaptive-pg"}, "prior starts a fresh network"),
])
def test_bad_settings_are_named(kw, match):
    with pytest.raises(ValueError, match=match):
        AdaptiveTrainConfig(**kw)
