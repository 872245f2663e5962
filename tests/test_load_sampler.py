"""Loading learned samplers of both kinds: agents.load_sampler takes either, agents.checkpoint.load_sampler
names the loader of an in-frame one, and misuse of a policy gets a clear error."""

from __future__ import annotations

import importlib.resources

import numpy as np
import pytest

import agents
from agents import checkpoint
from agents.adaptive import AdaptiveSamplerPolicy
from agents.checkpoint import SHIPPED_IN_FRAME_SAMPLERS, SHIPPED_SAMPLERS, LearnedPolicy


def shipped(name: str):
    return importlib.resources.as_file(importlib.resources.files("agents").joinpath("checkpoints", f"{name}.pt"))


@pytest.mark.parametrize("name", SHIPPED_SAMPLERS + SHIPPED_IN_FRAME_SAMPLERS)
def test_either_kind_loads_by_name_and_by_path(name):
    expected = LearnedPolicy if name in SHIPPED_SAMPLERS else AdaptiveSamplerPolicy
    by_name = agents.load_sampler(name)
    assert isinstance(by_name, expected) and by_name.name == name
    assert by_name.kind == ("one-shot" if name in SHIPPED_SAMPLERS else "in-frame")
    with shipped(name) as path:
        by_path = agents.load_sampler(path)
    assert isinstance(by_path, expected) and by_path.name == name


@pytest.mark.parametrize("name", SHIPPED_IN_FRAME_SAMPLERS)
def test_the_one_shot_loader_names_the_loader_of_an_in_frame_sampler(name):
    with pytest.raises(ValueError, match="in-frame sampler: load it with agents.load_sampler"):
        checkpoint.load_sampler(name)
    with shipped(name) as path, pytest.raises(ValueError, match="in-frame sampler: load it with agents.load_sampler"):
        checkpoint.load_sampler(path)


def test_kind_is_checked():
    with pytest.raises(ValueError, match="'adaptive-pg' is an in-frame sampler, not one-shot"):
        agents.load_sampler("adaptive-pg", kind="one-shot")
    with pytest.raises(ValueError, match="'ppo' is an one-shot sampler, not in-frame"):
        agents.load_sampler("ppo", kind="in-frame")
    with pytest.raises(ValueError, match="kind must be"):
        agents.load_sampler("ppo", kind="both")
    with pytest.raises(ValueError, match="unknown sampler 'adaptive-nope'.*adaptive-pg-prior"):
        agents.load_sampler("adaptive-nope")


def test_policies_refuse_the_wrong_observation_with_a_clear_error():
    one_shot, in_frame = agents.load_sampler("ngransac-supervised"), agents.load_sampler("adaptive-pg-prior")
    with pytest.raises(ValueError, match="act\\(\\) takes the observation dict"):
        one_shot.act(np.zeros((50, 14), np.float32))
    with pytest.raises(ValueError, match="mask of the leading shape"):
        one_shot.act({"features": np.zeros((50, 14), np.float32), "mask": np.ones(49)})
    with pytest.raises(ValueError, match="adaptive observation"):
        in_frame.act({"features": np.zeros((50, 14), np.float32), "mask": np.ones(50)})
    with pytest.raises(ValueError, match="expected 18 adaptive features"):
        in_frame.act({"features": np.zeros((50, 14), np.float32), "mask": np.ones(50), "globals": np.zeros(7)})
    with pytest.raises(ValueError, match="temperature"):
        agents.load_sampler("ppo", temperature=0.0)
