"""PPOConfig's checks of the policy's sizes: a config that loading would refuse cannot be trained."""

from __future__ import annotations

import sys

import pytest

from agents.network_size import MAX_NETWORK_PARAMETERS
from agents.ppo.config import PPOConfig


@pytest.mark.parametrize("sizes", [dict(width=8, blocks=1, critic_width=4, critic_hidden=5),
                                   dict(width=6, blocks=2, critic_width=None, critic_hidden=7),
                                   dict(width=5, blocks=3, critic_width=9, critic_hidden=3, share_trunk=True)])
def test_the_counted_parameters_are_those_of_the_policy_it_builds(sizes):
    import gymnasium

    import vo_gym  # noqa: F401
    from agents.ppo.config import policy_kwargs
    from agents.ppo.policy import EquivariantActorCriticPolicy

    config = PPOConfig(n_correspondences=12, **sizes)
    env = gymnasium.make(config.env_id, n_correspondences=12)
    policy = EquivariantActorCriticPolicy(env.observation_space, env.action_space, lambda _: 1e-4,
                                          **policy_kwargs(config))
    assert config.policy_parameters() == sum(p.numel() for p in policy.parameters())


@pytest.mark.parametrize("field, value, message", [
    ("width", 4097, "PPO: width must be an integer >= 1 and <= 4096, got 4097"),
    ("blocks", 0, "PPO: blocks must be an integer >= 1 and <= 4096, got 0"),
    ("critic_width", 5000, "PPO: critic_width must be None or an integer >= 1 and <= 4096, got 5000"),
    ("critic_width", 2.5, "PPO: critic_width must be None or an integer >= 1 and <= 4096, got 2.5"),
    ("critic_hidden", 10**6, "PPO: critic_hidden must be an integer >= 1 and <= 4096, got 1000000"),
])
def test_a_size_past_the_cap_is_refused_naming_it(field, value, message):
    with pytest.raises(ValueError) as err:
        PPOConfig(**{field: value})
    assert str(err.value) == message


def test_a_policy_over_the_parameter_cap_is_refused_before_anything_is_built():
    with pytest.raises(ValueError, match=r"width 1024, blocks 20, critic_width 32 and critic_hidden 64 make a policy "
                                         r"of 42,051,524 parameters, more than the 16,777,216 a checkpoint may hold"):
        PPOConfig(width=1024, blocks=20)
    # the largest of that shape the cap admits still goes through
    config = PPOConfig(width=1024, blocks=7)
    assert config.policy_parameters() <= MAX_NETWORK_PARAMETERS


def test_the_config_stays_torch_free():
    import subprocess

    code = "import sys; from agents.ppo.config import PPOConfig; PPOConfig(width=64); print('torch' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


@pytest.mark.parametrize("field, value, message", [
    ("timesteps", 10**400, "PPO: timesteps must be an integer >= 1 and <= 1000000000, got ~1e+400 (an integer of 401 digits)"),
    ("eval_every", 10**10, "PPO: eval_every must be an integer >= 1 and <= 1000000000, got 10000000000"),
    ("n_envs", 10**6, "PPO: n_envs must be an integer >= 1 and <= 1024, got 1000000"),
    ("n_correspondences", 10**9, "PPO: n_correspondences must be an integer >= 3 and <= 100000000, got 1000000000"),
    ("budget", 10**10, "PPO: budget must be an integer >= 1 and <= 1000000000, got 10000000000"),
    ("seed", -1, "PPO: seed must be an integer >= 0, got -1"),
])
def test_a_count_past_its_cap_is_refused_naming_it(field, value, message):
    with pytest.raises(ValueError) as err:
        PPOConfig(**{field: value})
    assert str(err.value) == message
