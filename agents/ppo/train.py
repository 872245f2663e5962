"""stable-baselines3 PPO on the environment through the equivariant custom policy.

The actor is :class:`agents.network.CorrespondenceNet` (per-correspondence
Gaussian means = its logits, one learned log-std), the critic pools its
global feature through a small MLP (:mod:`agents.ppo.policy`). Training runs on
SB3 vectorised envs (``DummyVecEnv`` or ``SubprocVecEnv`` via ``make_vec_env``)
with three callbacks: a progress bar, :class:`SuccessEvalCallback` (success
rate of the deterministic policy on held-out seeds at ``eval_epsilon``, logged
to TensorBoard, next to the uniform policy's on the same seeds) and SB3's
``CheckpointCallback``.

Outputs under ``out``:

- ``ppo.zip``: the SB3 model (what ``--resume`` loads); its ``policy_kwargs``
  carry the :class:`PPOConfig` (``train_config``). :func:`load_ppo` reads it
  without SB3's loader, which unpickles parts of the zip: nothing in a zip runs;
- ``ppo.pt``: the actor exported with :func:`agents.checkpoint.save_checkpoint`
  (config ``{"algo": "ppo", ...}``, the feature layout), readable by
  :meth:`agents.checkpoint.LearnedPolicy.from_checkpoint` and ``vo-gym evaluate
  --agent``; ``ppo-best.pt``: the actor of the best evaluation;
- ``checkpoints/ppo_<steps>_steps.zip`` (periodic), ``tb/`` (TensorBoard),
  ``training.json`` (config, evaluation history, wall time).

The deterministic action is the mean, i.e. the logits centred on the valid
slots, which the guided env softmaxes: exactly what ``LearnedPolicy`` returns
for the exported actor.

The settings and model building live in :mod:`agents.ppo.config`, the safe reading of a
zip in :mod:`agents.ppo.archive`; this module holds the callbacks and :func:`train_ppo`, and
re-exports the public names of both.
"""

from __future__ import annotations

import dataclasses
import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from stable_baselines3.common.callbacks import BaseCallback

from agents.checkpoint import LearnedPolicy, save_checkpoint
from agents.ppo.archive import first_line, load_ppo, read_ppo_config, zip_failure
from agents.ppo.config import RESUMABLE_FIELDS, PPOConfig, build_model, make_training_env, stored_config
from agents.rollout import success_rate

__all__ = [
    "export_actor",
    "SuccessEvalCallback",
    "train_ppo",
]


def export_actor(model, path: str | Path, config: PPOConfig, state: dict[str, Any] | None = None) -> Path:
    """Write the actor net with :func:`agents.checkpoint.save_checkpoint` (config ``{"algo": "ppo", ...}``)."""
    net = model.policy.action_net
    state = {"timesteps": int(model.num_timesteps), "log_std": float(model.policy.log_std.detach().mean()),
             **(state or {})}
    return save_checkpoint(path, net, {"algo": "ppo", **config.as_dict()}, state)


# --------------------------------------------------------------------------- callbacks


class ProgressCallback(BaseCallback):
    """A tqdm bar over environment steps, with the latest evaluation in its postfix."""

    def __init__(self, total: int, history: list[dict[str, Any]]) -> None:
        super().__init__()
        self.total, self.history, self.bar = total, history, None

    def _on_training_start(self) -> None:
        from tqdm.auto import tqdm

        self.bar = tqdm(total=self.total, desc="ppo", unit="step", dynamic_ncols=True)

    def _on_step(self) -> bool:
        self.bar.update(self.training_env.num_envs)
        if self.history:
            self.bar.set_postfix(eval_succ=f"{self.history[-1]['success']:.2f}", refresh=False)
        return True

    def _on_training_end(self) -> None:
        self.bar.close()


class WallTimeLimit(BaseCallback):
    """Stops training once ``seconds`` of wall time have passed since training started."""

    def __init__(self, seconds: float) -> None:
        super().__init__()
        self.seconds, self.start = float(seconds), 0.0

    def _on_training_start(self) -> None:
        self.start = time.perf_counter()

    def _on_step(self) -> bool:
        return time.perf_counter() - self.start < self.seconds


class SuccessEvalCallback(BaseCallback):
    """Success rate of the deterministic policy on held-out seeds; exports the actor each time.

    Logs ``eval/success_eps<e>``, ``eval/mean_reward`` and, once, ``eval/uniform_success_eps<e>``
    (the uniform policy on the same frames), plus ``train/success`` (frame success of the
    stochastic rollouts) at every rollout end.
    """

    def __init__(self, config: PPOConfig, out: Path, history: list[dict[str, Any]],
                 baseline: dict[str, float]) -> None:
        super().__init__()
        self.config, self.out, self.history, self.baseline = config, out, history, baseline
        self.every = config.eval_every
        self.next_eval = 0
        self.best = -1.0
        self.train_success: list[bool] = []
        self.tag = f"eps{config.eval_epsilon:g}"

    def _on_training_start(self) -> None:
        last = self.history[-1]["timesteps"] if self.history else None
        self.best = max((h["success"] for h in self.history), default=-1.0)
        self.next_eval = self.num_timesteps + (self.every if last is not None else 0)
        if "success" not in self.baseline:
            from agents.policies import make_heuristic

            s, r = success_rate(make_heuristic("uniform"), self.config.env_id, self.config.eval_env_kwargs(),
                                self.config.eval_seeds())
            self.baseline.update(success=s, mean_reward=r)
        self.logger.record(f"eval/uniform_success_{self.tag}", self.baseline["success"])

    def _on_step(self) -> bool:
        for info in self.locals.get("infos", []):
            if "success" in info:
                self.train_success.append(bool(info["success"]))
        if self.num_timesteps >= self.next_eval:
            self.evaluate()
            self.next_eval = self.num_timesteps + self.every
        return True

    def _on_rollout_end(self) -> None:
        if self.train_success:
            self.logger.record("train/success", float(np.mean(self.train_success)))
            self.train_success = []

    def _on_training_end(self) -> None:
        if not self.history or self.history[-1]["timesteps"] != self.num_timesteps:
            self.evaluate()
        self.logger.dump(self.num_timesteps)

    def evaluate(self) -> dict[str, Any]:
        net = self.model.policy.action_net
        was_training = net.training
        try:
            s, r = success_rate(LearnedPolicy(net, name="ppo"), self.config.env_id,
                                self.config.eval_env_kwargs(), self.config.eval_seeds())
        finally:
            net.train(was_training)
        entry = {"timesteps": int(self.num_timesteps), "success": s, "mean_reward": r,
                 "log_std": float(self.model.policy.log_std.detach().mean())}
        self.history.append(entry)
        self.logger.record(f"eval/success_{self.tag}", s)
        self.logger.record("eval/mean_reward", r)
        self.logger.record("eval/log_std", entry["log_std"])
        state = {"history": list(self.history), "uniform_success": self.baseline.get("success")}
        export_actor(self.model, self.out / "ppo.pt", self.config, state)
        if s > self.best:
            self.best = s
            export_actor(self.model, self.out / "ppo-best.pt", self.config, state)
        return entry


# --------------------------------------------------------------------------- training


@dataclass
class PPOResult:
    model: Any
    config: PPOConfig
    history: list[dict[str, Any]]
    uniform_success: float | None
    wall_s: float
    zip_path: Path
    checkpoint_path: Path


def train_ppo(config: PPOConfig, out: str | Path, resume: str | Path | None = None,
              progress: bool = True) -> PPOResult:
    """Train (or continue ``resume``, an SB3 zip, up to ``config.timesteps`` in total) and write the outputs.

    With ``resume`` the stored config is used except the fields of
    :data:`~agents.ppo.config.RESUMABLE_FIELDS` (``timesteps``, ``n_envs``, ``vec_env``, ``seed``, the
    evaluation/checkpoint periods and ``max_wall_s``), which come from ``config``; the others of
    ``config`` are not read (``vo-gym train --resume`` refuses them when given).
    """
    from stable_baselines3.common.callbacks import CallbackList, CheckpointCallback

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    # One intra-op thread: on a small shared machine OpenMP threads contend (docs/results.md, training).
    torch.set_num_threads(1)
    history: list[dict[str, Any]] = []
    baseline: dict[str, float] = {}
    if resume is not None:
        saved = read_ppo_config(resume)
        keep = {k: getattr(config, k) for k in RESUMABLE_FIELDS}
        config = dataclasses.replace(saved, **keep)
        previous = out / "training.json"
        if previous.is_file():
            try:
                data = json.loads(previous.read_text())
                history = list(data.get("history", []))
                if data.get("uniform_success") is not None:
                    baseline = {"success": data["uniform_success"], "mean_reward": data.get("uniform_mean_reward")}
            except (ValueError, OSError):
                history = []
    try:
        env = make_training_env(config)
    except (ValueError, TypeError) as err:
        if resume is None:
            raise
        # the resumed zip's stored environment settings (env_kwargs) do not fit this version's environment
        raise zip_failure(Path(resume), f"its train_config does not build the environment ({first_line(err)})") from None
    try:
        if resume is not None:
            model = load_ppo(resume, env=env)
            if model.seed != config.seed:  # a new seed for the continuation: its action noise too, not only its envs
                model.seed = config.seed
                model.set_random_seed(config.seed)
            model.policy.train_config = stored_config(config)
            model.policy_kwargs["train_config"] = stored_config(config)
            model.tensorboard_log = str(out / "tb")
        else:
            model = build_model(config, env, tensorboard_log=str(out / "tb"))
        remaining = config.timesteps - model.num_timesteps
        callbacks = [SuccessEvalCallback(config, out, history, baseline),
                     CheckpointCallback(save_freq=max(config.checkpoint_every // config.n_envs, 1),
                                        save_path=str(out / "checkpoints"), name_prefix="ppo")]
        if config.max_wall_s is not None:
            callbacks.append(WallTimeLimit(config.max_wall_s))
        if progress:
            callbacks.insert(0, ProgressCallback(max(remaining, 0), history))
        start = time.perf_counter()
        if remaining > 0:
            model.learn(total_timesteps=remaining, callback=CallbackList(callbacks), tb_log_name="ppo",
                        reset_num_timesteps=resume is None, progress_bar=False)
        wall = time.perf_counter() - start
        zip_path = out / "ppo.zip"
        model.save(str(zip_path))
        state = {"history": history, "uniform_success": baseline.get("success")}
        checkpoint = export_actor(model, out / "ppo.pt", config, state)
    finally:
        env.close()
    summary = {
        "algo": "ppo", "config": config.as_dict(), "timesteps": int(model.num_timesteps), "wall_s": round(wall, 1),
        "zip": str(zip_path), "checkpoint": str(checkpoint), "uniform_success": baseline.get("success"),
        "uniform_mean_reward": baseline.get("mean_reward"), "history": history,
    }
    (out / "training.json").write_text(json.dumps(summary, indent=2) + "\n")
    return PPOResult(model, config, history, baseline.get("success"), wall, zip_path, checkpoint)
