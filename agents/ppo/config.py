"""The PPO trainer's settings and how they become an environment and an SB3 model.

:class:`PPOConfig` holds every setting (it is stored in the SB3 zip and the exported
checkpoint); :func:`make_training_env` builds the vectorised environments and
:func:`build_model` a fresh SB3 ``PPO`` with the equivariant policy. Training:
:mod:`agents.ppo.train`; reading a zip back: :mod:`agents.ppo.archive`.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

from agents.network_size import MAX_NETWORK_PARAMETERS, MAX_NETWORK_SIZE, ppo_policy_parameters
from agents.training_limits import LEARNING_RATE, MAX_ENVS, MAX_TRAINING_STEPS
from stereovo.estimation.estimator_options import MAX_COUNT
from stereovo.options import Choice, Integer, Number, Option
from stereovo.simulation.config import MAX_CORRESPONDENCES, MAX_FRAMES
from vo_gym.features import FEATURE_LAYOUT_VERSION, FEATURE_NAMES, N_FEATURES
from vo_gym.settings import ContaminationRange, FieldError, check_fields

VEC_ENVS = ("dummy", "subproc")

_PPO_RULES: dict[str, Option] = {
    # counts within the caps of agents.training_limits, the simulator (frames, matches) and the estimator
    # (hypotheses), so that a typo fails here, naming the field, and not as an overflow once training runs
    **{name: Integer(low=1, high=MAX_TRAINING_STEPS) for name in ("timesteps", "n_steps", "batch_size", "n_epochs",
                                                                  "eval_every", "eval_frames", "checkpoint_every")},
    "n_envs": Integer(low=1, high=MAX_ENVS),
    "n_frames": Integer(low=1, high=MAX_FRAMES),
    "n_correspondences": Integer(low=3, high=MAX_CORRESPONDENCES),
    "budget": Integer(low=1, high=MAX_COUNT),
    "seed": Integer(low=0),
    # a policy a checkpoint can hold (agents.checkpoint and agents.ppo.archive refuse larger ones at load)
    **{name: Integer(low=1, high=MAX_NETWORK_SIZE) for name in ("width", "blocks", "critic_hidden")},
    "critic_width": Integer(low=1, high=MAX_NETWORK_SIZE, allow_none=True),
    "eval_n_correspondences": Integer(low=3, high=MAX_CORRESPONDENCES, allow_none=True),
    "max_wall_s": Number(low=0.0, low_open=True, allow_none=True, unit="s"),
    "vec_env": Choice(choices=VEC_ENVS),
    "epsilon_range": ContaminationRange(),
    "eval_epsilon": Number(low=0.0, high=1.0, high_open=True),
    "learning_rate": LEARNING_RATE,
    "clip_range": Number(low=0.0, low_open=True),
    "gamma": Number(low=0.0, high=1.0),
    "gae_lambda": Number(low=0.0, high=1.0),
}
"""The declarations :class:`PPOConfig` is checked and normalised by (:mod:`stereovo.options`)."""

RESUMABLE_FIELDS = ("timesteps", "n_envs", "vec_env", "seed", "eval_every", "checkpoint_every", "max_wall_s")
"""The fields a run resumed from its SB3 zip takes from the given config (:func:`agents.ppo.train.train_ppo`):
how long to train (``timesteps``, the new total; ``max_wall_s``), the workers, the seed of the
continuation and the evaluation and checkpoint periods. The others are the zip's: the network, the
environment and its reward, the PPO settings (the learning rate included) and the evaluation."""


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

    Why the defaults are these: exploration is Gaussian noise on every logit, and the share of a
    frame's outcome that one correspondence's noise explains shrinks with N, so PPO trains on a small
    N and is evaluated on N = 500; a wide initial std (log-std 1) and a small learning rate keep the
    PPO ratio, a product over all N slots, inside the clip range. The probes behind them are in
    ``docs/results.md`` (How the shipped samplers were trained).
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
        for name, value in check_fields(_PPO_RULES, vars(self), prefix="PPO: ").items():
            setattr(self, name, value)
        count = self.policy_parameters()
        if count > MAX_NETWORK_PARAMETERS:
            raise FieldError("width", f" {self.width}, blocks {self.blocks}, critic_width {self.critic_width} and "
                             f"critic_hidden {self.critic_hidden} make a policy of {count:,} parameters, more than "
                             f"the {MAX_NETWORK_PARAMETERS:,} a checkpoint may hold", prefix="PPO: ")
        if self.batch_size > self.n_steps * self.n_envs:
            raise FieldError("batch_size", f"={self.batch_size} exceeds the rollout size n_steps * n_envs = "
                                           f"{self.n_steps * self.n_envs}", prefix="PPO: ")
        self.env_kwargs = dict(self.env_kwargs)

    def policy_parameters(self) -> int:
        """The policy's parameter count (actor, critic trunk, critic MLP), from the sizes alone."""
        critic_width = self.width if self.critic_width is None or self.share_trunk else self.critic_width
        return ppo_policy_parameters(N_FEATURES, self.width, self.blocks, critic_width, self.critic_hidden,
                                     bool(self.share_trunk))

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


def build_model(config: PPOConfig, env, tensorboard_log: str | None = None, verbose: int = 0, setup: bool = True):
    """A fresh SB3 ``PPO`` with :class:`agents.ppo.policy.EquivariantActorCriticPolicy`.

    ``setup=False``: the object without its policy and buffers yet (SB3's ``_init_setup_model``), for
    :func:`load_ppo` to set the spaces first when there is no ``env``.
    """
    from stable_baselines3 import PPO

    from agents.ppo.policy import EquivariantActorCriticPolicy

    return PPO(
        EquivariantActorCriticPolicy, env, learning_rate=config.learning_rate, n_steps=config.n_steps,
        batch_size=config.batch_size, n_epochs=config.n_epochs, gamma=config.gamma, gae_lambda=config.gae_lambda,
        clip_range=config.clip_range, ent_coef=config.ent_coef, vf_coef=config.vf_coef,
        max_grad_norm=config.max_grad_norm, target_kl=config.target_kl, tensorboard_log=tensorboard_log,
        policy_kwargs=policy_kwargs(config), seed=config.seed, device="cpu", verbose=verbose,
        _init_setup_model=setup,
    )
