"""PPO through the equivariant custom policy: equivariance, trainable actor, a tiny run (SB3's env check: tests/vo_gym/test_env.py)."""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest
import torch

pytest.importorskip("stable_baselines3")

from stable_baselines3.common.utils import obs_as_tensor  # noqa: E402

import agents.ppo.train as ppo_train  # noqa: E402
from agents.checkpoint import LearnedPolicy, load_checkpoint  # noqa: E402
from agents.policies import make_heuristic  # noqa: E402
from agents.ppo.archive import load_ppo, load_ppo_actor, read_ppo_config  # noqa: E402
from agents.ppo.config import PPOConfig  # noqa: E402
from agents.ppo.train import train_ppo  # noqa: E402
from agents.ppo.policy import EquivariantActorCriticPolicy  # noqa: E402
from agents.rollout import success_rate  # noqa: E402
from vo_gym import FEATURE_LAYOUT_VERSION, FEATURE_NAMES, StereoVOEnv  # noqa: E402


pytestmark = pytest.mark.usefixtures("one_torch_thread")


def _policy(env: StereoVOEnv, **kwargs) -> EquivariantActorCriticPolicy:
    torch.manual_seed(0)
    return EquivariantActorCriticPolicy(
        env.observation_space, env.action_space, lambda _: 3e-4, width=16, blocks=1, critic_hidden=16, **kwargs
    )


def _batch(obs: dict) -> dict:
    return obs_as_tensor({k: v[None] for k, v in obs.items()}, torch.device("cpu"))


@pytest.mark.parametrize("share_trunk", [False, True])
def test_policy_is_permutation_equivariant_and_ignores_padding(share_trunk):
    env = StereoVOEnv(n_frames=2, n_correspondences=40, max_correspondences=48, budget=4)
    obs, _ = env.reset(seed=3)
    policy = _policy(env, share_trunk=share_trunk)
    with torch.no_grad():
        batch = _batch(obs)
        mean = policy.get_distribution(batch).distribution.mean[0]
        value = policy.predict_values(batch)[0]
        # Permute the 40 valid correspondences (padding stays at the end).
        perm = np.concatenate([np.random.default_rng(0).permutation(40), np.arange(40, 48)])
        permuted = {"features": obs["features"][perm], "mask": obs["mask"][perm]}
        pbatch = _batch(permuted)
        torch.testing.assert_close(policy.get_distribution(pbatch).distribution.mean[0], mean[perm],
                                   atol=1e-5, rtol=1e-5)
        torch.testing.assert_close(policy.predict_values(pbatch)[0], value, atol=1e-5, rtol=1e-5)
        # Garbage in the padded rows changes nothing.
        noisy = {"features": obs["features"].copy(), "mask": obs["mask"]}
        noisy["features"][40:] = 7.0
        nbatch = _batch(noisy)
        torch.testing.assert_close(policy.get_distribution(nbatch).distribution.mean[0, :40], mean[:40])
        torch.testing.assert_close(policy.predict_values(nbatch)[0], value)
        # Log-probabilities count the valid slots only.
        actions = torch.zeros(1, 48)
        _, log_prob, entropy = policy.evaluate_actions(batch, actions)
        actions[0, 40:] = 5.0
        _, log_prob_padded, _ = policy.evaluate_actions(batch, actions)
        torch.testing.assert_close(log_prob, log_prob_padded)
        assert entropy.shape == (1,)
    # The deterministic action is the exported actor's (LearnedPolicy) on the valid slots.
    det, _ = policy.predict(obs, deterministic=True)
    np.testing.assert_allclose(det[:40], LearnedPolicy(policy.action_net).act(obs)[:40], atol=1e-5)


def test_optimizer_trains_the_actor_net_and_the_log_std():
    env = StereoVOEnv(n_frames=2, n_correspondences=32, budget=4)
    obs, _ = env.reset(seed=0)
    policy = _policy(env)
    in_optimizer = {id(p) for group in policy.optimizer.param_groups for p in group["params"]}
    actor = list(policy.action_net.parameters())
    assert all(id(p) in in_optimizer for p in actor)
    assert all(id(p) in in_optimizer for p in policy.value_net.parameters())
    assert id(policy.log_std) in in_optimizer and policy.log_std.shape == (1,)
    # No dense layer over all action dimensions is left anywhere in the policy.
    assert not any(isinstance(m, torch.nn.Linear) and m.out_features == 32 for m in policy.modules())

    before = [p.detach().clone() for p in actor]
    batch = _batch(obs)
    actions = torch.as_tensor(np.random.default_rng(0).normal(size=(1, 32)), dtype=torch.float32)
    values, log_prob, _ = policy.evaluate_actions(batch, actions)
    loss = -log_prob.mean() + values.pow(2).mean()
    policy.optimizer.zero_grad()
    loss.backward()
    policy.optimizer.step()
    assert any(not torch.equal(b, p) for b, p in zip(before, actor))


def test_tiny_ppo_run_writes_checkpoints_that_load_and_resume(tmp_path, capsys):
    config = PPOConfig(
        timesteps=128, n_envs=2, n_steps=32, batch_size=32, n_epochs=1, n_frames=4, n_correspondences=64,
        budget=8, width=8, blocks=1, critic_width=8, critic_hidden=8, eval_every=64, eval_frames=8,
        eval_n_correspondences=64, checkpoint_every=64,
    )
    result = train_ppo(config, tmp_path, progress=False)
    assert result.model.num_timesteps == 128
    for name in ("ppo.zip", "ppo.pt", "ppo-best.pt", "training.json"):
        assert (tmp_path / name).is_file(), name
    assert list((tmp_path / "checkpoints").glob("ppo_*_steps.zip"))
    assert any((tmp_path / "tb").rglob("events.out.tfevents.*"))
    assert [h["timesteps"] for h in result.history][0] <= 2 and result.history[-1]["timesteps"] == 128
    # The uniform baseline: the uniform policy on the evaluation's episodes, one from each seed eval_seed + i
    # (8 frames: two 4-frame episodes) at eps 0.8 with the evaluation's 64 matches.
    # Its mean reward, stored beside it, tells those episodes apart from others with the same few successes.
    uniform, reward = success_rate(make_heuristic("uniform"), "vo_gym/StereoVO-v0",
                                   {"n_frames": 4, "n_correspondences": 64, "outlier_ratio": 0.8, "budget": 8,
                                    "reward_mode": "supervised"}, [10_000, 10_001])
    assert result.uniform_success == uniform
    summary = json.loads((tmp_path / "training.json").read_text())
    assert (summary["uniform_success"], summary["uniform_mean_reward"]) == (uniform, reward)

    # The exported actor: config and feature layout, readable by LearnedPolicy, same action as SB3's mean.
    net, payload = load_checkpoint(tmp_path / "ppo.pt")
    assert payload["config"]["algo"] == "ppo" and payload["config"]["n_correspondences"] == 64
    assert payload["feature_names"] == list(FEATURE_NAMES)
    assert payload["feature_layout_version"] == FEATURE_LAYOUT_VERSION
    policy = LearnedPolicy.from_checkpoint(tmp_path / "ppo.pt")
    env = StereoVOEnv(n_frames=2, n_correspondences=64, budget=8)
    obs, _ = env.reset(seed=5)
    sb3_action, _ = result.model.predict(obs, deterministic=True)
    np.testing.assert_allclose(policy.act(obs), sb3_action, atol=1e-5)
    zip_net = load_ppo_actor(tmp_path / "ppo.zip")
    np.testing.assert_allclose(LearnedPolicy(zip_net).act(obs), sb3_action, atol=1e-5)
    assert read_ppo_config(tmp_path / "ppo.zip") == result.config

    # --resume continues the SB3 model to the new total.
    from vo_gym_cli.main import main

    code = main(["train", "--algo", "ppo", "--out", str(tmp_path), "--resume", str(tmp_path / "ppo.zip"),
                 "--timesteps", "192", "--no-progress"])
    assert code == 0
    assert "success at eps 0.8" in capsys.readouterr().out
    assert load_ppo(tmp_path / "ppo.zip").num_timesteps == 192
    assert main(["train", "--algo", "ppo", "--out", str(tmp_path), "--resume", str(tmp_path / "ppo.pt")]) == 2
    assert "resumes from the SB3 model zip" in capsys.readouterr().err


def test_ppo_best_holds_the_actor_of_the_best_evaluation(tmp_path, monkeypatch):
    # Three evaluations (after the first step, after the first update at step 17, at the end after the second
    # update), stubbed to score 0.2, 0.6, 0.4: ppo-best.pt holds the actor the second one saw, ppo.pt the last.
    config = PPOConfig(
        timesteps=32, n_envs=1, n_steps=16, batch_size=16, n_epochs=1, n_frames=4, n_correspondences=32,
        budget=4, width=8, blocks=1, critic_width=8, critic_hidden=8, eval_every=16, eval_frames=4,
        eval_n_correspondences=32, checkpoint_every=1000, learning_rate=1e-2,
    )
    scores, seen = iter([0.2, 0.6, 0.4]), []

    def stub(policy, env_id, env_kwargs, seeds):
        if policy.name == "uniform":  # the baseline, once
            return 0.5, 0.0
        seen.append({k: v.detach().clone() for k, v in policy.net.state_dict().items()})
        return next(scores), 0.0

    monkeypatch.setattr(ppo_train, "success_rate", stub)
    result = train_ppo(config, tmp_path, progress=False)
    assert [(h["timesteps"], h["success"]) for h in result.history] == [(1, 0.2), (17, 0.6), (32, 0.4)]
    assert len(seen) == 3
    for a, b in itertools.combinations(seen, 2):  # each update moved the actor
        assert any(not torch.equal(a[k], b[k]) for k in a)

    def assert_state(path, expected):
        net, payload = load_checkpoint(path)
        state = net.state_dict()
        assert state.keys() == expected.keys()
        for k in expected:
            assert torch.equal(state[k], expected[k]), (path.name, k)
        return payload

    best = assert_state(tmp_path / "ppo-best.pt", seen[1])
    assert [h["success"] for h in best["trainer_state"]["history"]] == [0.2, 0.6]
    assert_state(tmp_path / "ppo.pt", seen[2])
