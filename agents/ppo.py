"""stable-baselines3 PPO on the environment through the equivariant custom policy.

The actor is :class:`agents.network.CorrespondenceNet` (per-correspondence
Gaussian means = its logits, one learned log-std), the critic pools its
global feature through a small MLP (:mod:`agents.sb3_policy`). Training runs on
SB3 vectorised envs (``DummyVecEnv`` or ``SubprocVecEnv`` via ``make_vec_env``)
with three callbacks: a progress bar, :class:`SuccessEvalCallback` (success
rate of the deterministic policy on held-out seeds at ``eval_epsilon``, logged
to TensorBoard, next to the uniform policy's on the same seeds) and SB3's
``CheckpointCallback``.

Outputs under ``out``:

- ``ppo.zip``: the SB3 model (what ``--resume`` loads); its ``policy_kwargs``
  carry the :class:`PPOConfig` (``train_config``);
- ``ppo.pt``: the actor exported with :func:`agents.checkpoint.save_checkpoint`
  (config ``{"algo": "ppo", ...}``, the feature layout), readable by
  :meth:`agents.checkpoint.LearnedPolicy.from_checkpoint` and ``vo-gym evaluate
  --agent``; ``ppo-best.pt``: the actor of the best evaluation;
- ``checkpoints/ppo_<steps>_steps.zip`` (periodic), ``tb/`` (TensorBoard),
  ``training.json`` (config, evaluation history, wall time).

The deterministic action is the mean, i.e. the logits centred on the valid
slots, which the guided env softmaxes: exactly what ``LearnedPolicy`` returns
for the exported actor.
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from stable_baselines3.common.callbacks import BaseCallback

from agents.checkpoint import LearnedPolicy, save_checkpoint
from agents.network import CorrespondenceNet
from agents.rollout import success_rate
from vo_gym.features import FEATURE_LAYOUT_VERSION, FEATURE_NAMES, check_feature_layout

__all__ = [
    "PPOConfig",
    "make_training_env",
    "build_model",
    "export_actor",
    "load_ppo",
    "load_ppo_actor",
    "read_ppo_config",
    "SuccessEvalCallback",
    "train_ppo",
]

VEC_ENVS = ("dummy", "subproc")


@dataclass
class PPOConfig:
    """PPO training settings (saved in the SB3 zip and the exported checkpoint).

    Environment: ``env_id`` with ``n_frames`` frame pairs per episode, ``n_correspondences``,
    contamination drawn per frame from ``epsilon_range``, ``budget`` hypotheses, ``reward_mode``
    and any further ``env_kwargs``. Evaluation: every ``eval_every`` environment steps (rounded up to
    a whole vectorised step), ``eval_frames`` frames at ``eval_epsilon`` from seeds ``eval_seed + i``,
    with ``eval_n_correspondences`` matches per frame (None: the training ``n_correspondences``; the
    network serves any N, so training on fewer matches and evaluating on more is legitimate).
    The remaining fields are SB3 ``PPO`` arguments and the policy's sizes.

    Defaults are what trained in minutes on 2 CPU cores (measured, see the probes in the PPO report):
    exploration is Gaussian noise on every logit, and the share of a frame's outcome that one
    correspondence's noise explains shrinks with N, so PPO trains on N = 100 (about 5x faster steps
    too) and is evaluated on N = 500; a wide initial std (log-std 1) and a learning rate of 1e-4 keep
    the PPO ratio, a product over all N slots, inside the clip range (approx. KL ~0.02 per update).
    With N = 500 and log-std 0 nothing was learnt in 6000 steps.
    """

    env_id: str = "vo_gym/StereoVO-v0"
    n_envs: int = 2
    vec_env: str = "dummy"
    seed: int = 0
    timesteps: int = 20_000
    # environment
    n_frames: int = 8
    n_correspondences: int = 100
    epsilon_range: tuple[float, float] = (0.3, 0.9)
    budget: int = 16
    reward_mode: str = "supervised"
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    # PPO
    n_steps: int = 256
    batch_size: int = 128
    n_epochs: int = 4
    learning_rate: float = 1e-4
    gamma: float = 0.5
    gae_lambda: float = 0.9
    clip_range: float = 0.2
    ent_coef: float = 0.0
    vf_coef: float = 0.5
    max_grad_norm: float = 0.5
    target_kl: float | None = None
    # policy
    width: int = 32
    blocks: int = 3
    critic_width: int | None = 32
    critic_hidden: int = 64
    share_trunk: bool = False
    log_std_init: float = 1.0
    # evaluation and checkpoints
    eval_every: int = 2000
    eval_frames: int = 100
    eval_epsilon: float = 0.8
    eval_n_correspondences: int | None = 500
    eval_seed: int = 10_000
    checkpoint_every: int = 5000
    max_wall_s: float | None = None

    def __post_init__(self) -> None:
        for name in ("n_envs", "timesteps", "n_frames", "n_correspondences", "budget", "n_steps", "batch_size",
                     "n_epochs", "width", "blocks", "critic_hidden", "eval_every", "eval_frames", "checkpoint_every"):
            value = getattr(self, name)
            if isinstance(value, bool) or int(value) != value or value < 1:
                raise ValueError(f"PPO: {name} must be an integer >= 1, got {value!r}")
            setattr(self, name, int(value))
        if self.eval_n_correspondences is not None and (
            int(self.eval_n_correspondences) != self.eval_n_correspondences or self.eval_n_correspondences < 3
        ):
            raise ValueError(f"PPO: eval_n_correspondences must be None or an integer >= 3, got "
                             f"{self.eval_n_correspondences!r}")
        if self.max_wall_s is not None and not self.max_wall_s > 0:
            raise ValueError(f"PPO: max_wall_s must be None or > 0 seconds, got {self.max_wall_s!r}")
        if self.vec_env not in VEC_ENVS:
            raise ValueError(f"PPO: vec_env must be one of {VEC_ENVS}, got {self.vec_env!r}")
        lo, hi = (float(x) for x in self.epsilon_range)
        if not 0.0 <= lo <= hi < 1.0:
            raise ValueError(f"PPO: epsilon_range must satisfy 0 <= low <= high < 1, got {self.epsilon_range}")
        self.epsilon_range = (lo, hi)
        if not 0.0 <= self.eval_epsilon < 1.0:
            raise ValueError(f"PPO: eval_epsilon must be in [0, 1), got {self.eval_epsilon}")
        if self.batch_size > self.n_steps * self.n_envs:
            raise ValueError(
                f"PPO: batch_size={self.batch_size} exceeds the rollout size n_steps * n_envs = "
                f"{self.n_steps * self.n_envs}"
            )
        for name in ("learning_rate", "clip_range"):
            if not getattr(self, name) > 0:
                raise ValueError(f"PPO: {name} must be > 0, got {getattr(self, name)!r}")
        if not (0.0 <= self.gamma <= 1.0 and 0.0 <= self.gae_lambda <= 1.0):
            raise ValueError(f"PPO: gamma and gae_lambda must be in [0, 1], got {self.gamma}, {self.gae_lambda}")
        self.env_kwargs = dict(self.env_kwargs)

    def train_env_kwargs(self) -> dict[str, Any]:
        return {**self.env_kwargs, "n_frames": self.n_frames, "n_correspondences": self.n_correspondences,
                "outlier_ratio": self.epsilon_range, "budget": self.budget, "reward_mode": self.reward_mode}

    def eval_env_kwargs(self) -> dict[str, Any]:
        n = self.n_correspondences if self.eval_n_correspondences is None else self.eval_n_correspondences
        return {**self.train_env_kwargs(), "outlier_ratio": float(self.eval_epsilon), "n_correspondences": n}

    def eval_seeds(self) -> list[int]:
        return [self.eval_seed + i for i in range(math.ceil(self.eval_frames / self.n_frames))]

    def as_dict(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        d["epsilon_range"] = list(self.epsilon_range)
        return d

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> "PPOConfig":
        known = {f.name for f in dataclasses.fields(cls)}
        data = {k: v for k, v in data.items() if k in known}
        if "epsilon_range" in data:
            data["epsilon_range"] = tuple(data["epsilon_range"])
        return cls(**data)


# --------------------------------------------------------------------------- building blocks


def make_training_env(config: PPOConfig, seed: int | None = None):
    """``config.n_envs`` monitored envs in a ``DummyVecEnv`` / ``SubprocVecEnv``, seeded ``seed + rank``."""
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    import vo_gym  # noqa: F401  (registers the ids)

    cls = SubprocVecEnv if config.vec_env == "subproc" else DummyVecEnv
    return make_vec_env(
        config.env_id, n_envs=config.n_envs, seed=config.seed if seed is None else seed,
        env_kwargs=config.train_env_kwargs(), vec_env_cls=cls,
    )


def stored_config(config: PPOConfig) -> dict[str, Any]:
    """What the SB3 zip carries in ``policy_kwargs["train_config"]``: the config and the feature layout."""
    return {**config.as_dict(), "feature_names": list(FEATURE_NAMES), "feature_layout_version": FEATURE_LAYOUT_VERSION}


def policy_kwargs(config: PPOConfig) -> dict[str, Any]:
    return {
        "width": config.width, "blocks": config.blocks, "critic_width": config.critic_width,
        "critic_hidden": config.critic_hidden, "share_trunk": config.share_trunk,
        "log_std_init": config.log_std_init, "train_config": stored_config(config),
    }


def build_model(config: PPOConfig, env, tensorboard_log: str | None = None, verbose: int = 0):
    """A fresh SB3 ``PPO`` with :class:`agents.sb3_policy.EquivariantActorCriticPolicy`."""
    from stable_baselines3 import PPO

    from agents.sb3_policy import EquivariantActorCriticPolicy

    return PPO(
        EquivariantActorCriticPolicy, env, learning_rate=config.learning_rate, n_steps=config.n_steps,
        batch_size=config.batch_size, n_epochs=config.n_epochs, gamma=config.gamma, gae_lambda=config.gae_lambda,
        clip_range=config.clip_range, ent_coef=config.ent_coef, vf_coef=config.vf_coef,
        max_grad_norm=config.max_grad_norm, target_kl=config.target_kl, tensorboard_log=tensorboard_log,
        policy_kwargs=policy_kwargs(config), seed=config.seed, device="cpu", verbose=verbose,
    )


def _stored_config(path: str | Path) -> dict[str, Any]:
    from stable_baselines3.common.save_util import load_from_zip_file

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no PPO model at {path}")
    try:
        data, _, _ = load_from_zip_file(path, load_data=True, device="cpu")
    except Exception as err:  # noqa: BLE001 - any unreadable archive gets one clear message
        raise ValueError(f"{path} is not a stable-baselines3 model zip: {err}") from None
    stored = (data or {}).get("policy_kwargs", {}).get("train_config")
    if not stored:
        raise ValueError(f"{path} is an SB3 model but not a vo-gym PPO one (no train_config in its policy_kwargs)")
    try:
        check_feature_layout(stored.get("feature_names", ()), stored.get("feature_layout_version", -1))
    except ValueError as err:
        raise ValueError(f"PPO model {path} was trained on another feature layout: {err}") from None
    return stored


def read_ppo_config(path: str | Path) -> PPOConfig:
    """The :class:`PPOConfig` stored in a PPO zip written here.

    Raises:
        FileNotFoundError: no such file.
        ValueError: not an SB3 zip, not one trained by this module, or another feature layout.
    """
    return PPOConfig.from_dict(_stored_config(path))


def load_ppo(path: str | Path, env=None):
    """Load a PPO zip (``env``: a VecEnv to continue training on, or None to only predict)."""
    from stable_baselines3 import PPO

    _stored_config(path)  # clear errors first
    return PPO.load(str(path), env=env, device="cpu")


def load_ppo_actor(path: str | Path) -> CorrespondenceNet:
    """The actor net of a PPO zip (eval mode), after checking its feature layout."""
    return load_ppo(path).policy.action_net.eval()


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

    With ``resume`` the stored config is used except ``timesteps``, ``n_envs``, ``vec_env``,
    ``seed`` and the evaluation/checkpoint periods, which come from ``config``.
    """
    from stable_baselines3.common.callbacks import CallbackList, CheckpointCallback

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    # One intra-op thread: on a small shared machine OpenMP threads contend and run 10-100x slower.
    torch.set_num_threads(1)
    history: list[dict[str, Any]] = []
    baseline: dict[str, float] = {}
    if resume is not None:
        saved = read_ppo_config(resume)
        keep = {k: getattr(config, k) for k in ("timesteps", "n_envs", "vec_env", "seed", "eval_every",
                                                 "checkpoint_every", "max_wall_s")}
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
    env = make_training_env(config)
    try:
        if resume is not None:
            model = load_ppo(resume, env=env)
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
