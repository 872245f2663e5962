"""``vo-gym train --algo ppo`` options reach agents.ppo.config.PPOConfig as given (no hidden defaults)."""

from __future__ import annotations

import argparse

import pytest

pytest.importorskip("stable_baselines3")

from agents.ppo.config import PPOConfig  # noqa: E402
from vo_gym_cli.commands import train  # noqa: E402


def _config(*argv: str) -> PPOConfig:
    parser = argparse.ArgumentParser()
    train.add_parser(parser)
    return train.ppo_config_from_args(parser.parse_args(["--algo", "ppo", *argv]))


@pytest.mark.parametrize("every", [250, 1000, 2000, 3])
def test_eval_every_is_taken_as_given(every):
    # 250 was once the shared option's default, and a given 250 silently became PPOConfig's 2000.
    assert _config("--eval-every", str(every)).eval_every == every


def test_options_left_out_keep_the_config_defaults():
    config, default = _config(), PPOConfig()
    assert config == default
    assert config.eval_every == 2000


def test_ppo_options_are_mapped_to_their_fields():
    config = _config("--epsilon", "0.4:0.7", "--frames-per-episode", "5", "--ppo-lr", "3e-4", "--max-minutes", "2",
                     "--eval-n", "200", "--n-envs", "1", "--batch-size", "64")
    assert config.epsilon_range == (0.4, 0.7)
    assert (config.n_frames, config.learning_rate, config.max_wall_s) == (5, 3e-4, 120.0)
    assert (config.eval_n_correspondences, config.n_envs, config.batch_size) == (200, 1, 64)
