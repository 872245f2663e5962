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
"""

from __future__ import annotations

import dataclasses
import io
import json
import math
import pickle
import time
import warnings
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from stable_baselines3.common.callbacks import BaseCallback

from agents.checkpoint import CheckpointError, LearnedPolicy, save_checkpoint
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


def build_model(config: PPOConfig, env, tensorboard_log: str | None = None, verbose: int = 0, setup: bool = True):
    """A fresh SB3 ``PPO`` with :class:`agents.sb3_policy.EquivariantActorCriticPolicy`.

    ``setup=False``: the object without its policy and buffers yet (SB3's ``_init_setup_model``), for
    :func:`load_ppo` to set the spaces first when there is no ``env``.
    """
    from stable_baselines3 import PPO

    from agents.sb3_policy import EquivariantActorCriticPolicy

    return PPO(
        EquivariantActorCriticPolicy, env, learning_rate=config.learning_rate, n_steps=config.n_steps,
        batch_size=config.batch_size, n_epochs=config.n_epochs, gamma=config.gamma, gae_lambda=config.gae_lambda,
        clip_range=config.clip_range, ent_coef=config.ent_coef, vf_coef=config.vf_coef,
        max_grad_norm=config.max_grad_norm, target_kl=config.target_kl, tensorboard_log=tensorboard_log,
        policy_kwargs=policy_kwargs(config), seed=config.seed, device="cpu", verbose=verbose,
        _init_setup_model=setup,
    )


# --------------------------------------------------------------------------- loading a PPO zip
#
# An SB3 zip's ``data`` entry is JSON, but SB3 stores what JSON cannot hold (the policy class,
# the spaces, the schedules, the rollout buffer class, the episode buffers) as base64 cloudpickle
# under ":serialized:", and ``PPO.load`` unpickles them: a crafted zip would run code. So nothing
# here goes through SB3's loader. The zip is opened with :mod:`zipfile`, ``data`` is read with
# ``json.loads`` only, and the model is rebuilt from this module's own code and the plain
# ``train_config`` it stores (class, spaces from the environment, constant schedules); no
# ":serialized:" entry is ever decoded. The weights (``policy.pth``, ``policy.optimizer.pth``)
# are read with ``torch.load(weights_only=True)``: tensors and plain data only.

ZIP_DATA = "data"
ZIP_POLICY = "policy.pth"
ZIP_OPTIMIZER = "policy.optimizer.pth"
MAX_ZIP_MEMBER_BYTES = 1 << 30  # a larger member is not something this module wrote (refuse, do not inflate)
# Plain counters of ``data`` restored on load (everything else is rebuilt from the config).
ZIP_COUNTERS = ("num_timesteps", "_n_updates", "_episode_num")


def _zip_fail(path: Path, what: str) -> CheckpointError:
    return CheckpointError(f"PPO model {path}: {what}")


def _first_line(err: BaseException) -> str:
    return (str(err).strip().splitlines() or [type(err).__name__])[0][:160]


def _read_zip(path: str | Path, need_optimizer: bool) -> tuple[Path, dict[str, Any], dict[str, bytes]]:
    """``(path, data, members)``: the JSON ``data`` (plain values; serialized entries left as they are)
    and the raw bytes of the weight members (the optimizer's where present; required with ``need_optimizer``)."""
    path = Path(path)
    if not path.is_file():
        if path.exists():
            raise _zip_fail(path, "is not a file")
        raise FileNotFoundError(f"no PPO model at {path}")
    try:
        if path.stat().st_size == 0:
            raise _zip_fail(path, "is empty")
        with zipfile.ZipFile(path) as archive:
            infos = {info.filename: info for info in archive.infolist()}
            if ZIP_DATA not in infos:
                raise _zip_fail(path, f"is a zip archive but not a stable-baselines3 model (no {ZIP_DATA!r} entry)")
            wanted = [ZIP_DATA, ZIP_POLICY] + ([ZIP_OPTIMIZER] if need_optimizer or ZIP_OPTIMIZER in infos else [])
            for name in wanted[1:]:
                if name not in infos:
                    raise _zip_fail(path, f"holds no {name!r} entry (the {'policy weights' if name == ZIP_POLICY else 'optimizer state'})")
            for name in wanted:
                if infos[name].file_size > MAX_ZIP_MEMBER_BYTES:
                    raise _zip_fail(path, f"its {name!r} entry is {infos[name].file_size} bytes, more than a model holds")
            members = {name: archive.read(name) for name in wanted}
    except CheckpointError:
        raise
    except zipfile.BadZipFile as err:
        text = str(err)
        if "File is not a zip file" in text or not zipfile.is_zipfile(path):
            raise _zip_fail(path, "is not a zip archive (not a stable-baselines3 model, or truncated)") from None
        raise _zip_fail(path, f"is a corrupt zip archive ({_first_line(err)})") from None
    except (OSError, EOFError, ValueError, NotImplementedError, RuntimeError) as err:  # unreadable, truncated, bad compression
        raise _zip_fail(path, f"cannot be read as a zip archive ({type(err).__name__}: {_first_line(err)})") from None
    try:
        data = json.loads(members.pop(ZIP_DATA).decode("utf-8"))
    except (ValueError, RecursionError) as err:  # JSONDecodeError and UnicodeDecodeError are ValueErrors
        raise _zip_fail(path, f"its {ZIP_DATA!r} entry is not JSON ({_first_line(err)})") from None
    if not isinstance(data, dict):
        raise _zip_fail(path, f"its {ZIP_DATA!r} entry must be a JSON object, got {type(data).__name__}")
    return path, data, members


def _zip_config(path: Path, data: dict[str, Any]) -> tuple[PPOConfig, dict[str, Any]]:
    """The :class:`PPOConfig` and the stored ``train_config`` of a zip's ``data`` (plain JSON only)."""
    kwargs = data.get("policy_kwargs")
    stored = kwargs.get("train_config") if isinstance(kwargs, dict) else None
    if not isinstance(stored, dict) or not stored or ":serialized:" in stored:
        raise _zip_fail(path, "is an SB3 model but not a vo-gym PPO one (no plain train_config in its policy_kwargs)")
    try:
        check_feature_layout(stored.get("feature_names", ()), stored.get("feature_layout_version", -1))
    except (ValueError, TypeError) as err:
        raise CheckpointError(f"PPO model {path} was trained on another feature layout: {_first_line(err)}") from None
    try:
        config = PPOConfig.from_dict(stored)
    except (ValueError, TypeError, KeyError) as err:
        raise _zip_fail(path, f"its train_config is not a valid PPO config ({_first_line(err)})") from None
    _check_stored_env_id(path, config.env_id)
    return config, stored


def _check_stored_env_id(path: Path, env_id: Any) -> None:
    """Only an id already registered: gymnasium imports the module of a ``"module:Env"`` id, which
    would let a file choose code to import."""
    import gymnasium as gym

    import vo_gym  # noqa: F401  (registers the ids)

    if not isinstance(env_id, str) or ":" in env_id or env_id not in gym.registry:
        raise _zip_fail(path, f"its train_config names env_id {env_id!r}, not a registered environment")


def _zip_tensors(path: Path, name: str, raw: bytes) -> Any:
    """``torch.load(weights_only=True)`` of one member: tensors and plain data, nothing run."""
    try:
        with warnings.catch_warnings():  # torch warns about odd pickle protocols: the error below says it in one line
            warnings.simplefilter("ignore")
            return torch.load(io.BytesIO(raw), map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as err:
        if "global" in str(err).lower() or "Unsupported class" in str(err):
            raise _zip_fail(path, f"its {name!r} entry refused: it holds Python objects other than tensors and "
                                  "plain data, which could run code when unpickled (nothing was run)") from None
        detail = "pickle opcodes outside torch's weights-only subset" if "Unsupported operand" in str(err) \
            else _first_line(err)
        raise _zip_fail(path, f"its {name!r} entry is not a torch file the weights-only loader reads ({detail}; "
                              "nothing was run)") from None
    except Exception as err:  # noqa: BLE001 - weights_only parsing of untrusted bytes: any failure is one line
        raise _zip_fail(path, f"its {name!r} entry is not a readable torch file "
                              f"({type(err).__name__}: {_first_line(err)})") from None


def _plain_count(path: Path, data: dict[str, Any], key: str) -> int:
    value = data.get(key, 0)
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise _zip_fail(path, f"its {key!r} must be an integer >= 0, got {value!r}")
    return value


def read_ppo_config(path: str | Path) -> PPOConfig:
    """The :class:`PPOConfig` stored in a PPO zip written here (read as JSON: nothing in it is run).

    Raises:
        FileNotFoundError: no such file.
        CheckpointError: (a ``ValueError``) not an SB3 zip, not one trained by this module, or another
            feature layout; one line naming the file and what is wrong.
    """
    path, data, _ = _read_zip(path, need_optimizer=False)
    return _zip_config(path, data)[0]


def load_ppo(path: str | Path, env=None):
    """Load a PPO zip written here (``env``: a VecEnv to continue training on, or None to only predict).

    Nothing in the file runs: the model is built by :func:`build_model` from the zip's plain
    ``train_config`` (its spaces from ``env``, or from the configured environment), then the
    policy weights, the optimizer state (required with ``env``) and the counters
    (``num_timesteps``, ``_n_updates``, ``_episode_num``) and the seed are put back. The cloudpickled
    entries SB3 writes (episode buffers, last observation) are not restored: continuing training
    resets the environment, as ``PPO.load(..., env=env)`` does.

    Raises:
        FileNotFoundError: no such file.
        CheckpointError: (a ``ValueError``) any unusable file, one line naming it and what is wrong.
    """
    path, data, members = _read_zip(path, need_optimizer=env is not None)
    config, _ = _zip_config(path, data)
    seed = data.get("seed", config.seed)
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int)):
        raise _zip_fail(path, f"its 'seed' must be an integer or null, got {seed!r}")
    counters = {key: _plain_count(path, data, key) for key in ZIP_COUNTERS}
    policy_state = _zip_tensors(path, ZIP_POLICY, members[ZIP_POLICY])
    if not isinstance(policy_state, dict) or not all(
            isinstance(k, str) and isinstance(v, torch.Tensor) for k, v in policy_state.items()):
        raise _zip_fail(path, f"its {ZIP_POLICY!r} entry must map parameter names to tensors")
    optimizer_state = None
    if ZIP_OPTIMIZER in members:
        optimizer_state = _zip_tensors(path, ZIP_OPTIMIZER, members[ZIP_OPTIMIZER])
        if not isinstance(optimizer_state, dict):
            raise _zip_fail(path, f"its {ZIP_OPTIMIZER!r} entry must be an optimizer state dict")

    model = build_model(dataclasses.replace(config, seed=seed), env, setup=False)
    if env is None:  # predicting only: the spaces of the environment the model was trained on
        import gymnasium as gym

        try:
            probe = gym.make(config.env_id, **config.train_env_kwargs())
        except (ValueError, TypeError) as err:
            raise _zip_fail(path, f"its train_config does not build the environment ({_first_line(err)})") from None
        model.observation_space, model.action_space, model.n_envs = probe.observation_space, probe.action_space, 1
        probe.close()
    # What SB3's own loader does after building the object without a model (``_init_setup_model=False``).
    model._setup_model()
    try:
        model.policy.load_state_dict(policy_state)
    except RuntimeError as err:
        lines = [ln.strip() for ln in str(err).splitlines() if ln.strip()]
        detail = lines[1] if len(lines) > 1 else (lines[0] if lines else "")
        raise _zip_fail(path, f"its policy weights do not fit the policy its train_config declares ({detail[:200]})") from None
    if optimizer_state is not None:
        try:
            model.policy.optimizer.load_state_dict(optimizer_state)
        except (ValueError, KeyError, TypeError, RuntimeError, IndexError) as err:
            raise _zip_fail(path, f"its optimizer state does not fit the policy ({type(err).__name__}: "
                                  f"{_first_line(err)})") from None
    for key, value in counters.items():
        setattr(model, key, value)
    return model


def load_ppo_actor(path: str | Path) -> CorrespondenceNet:
    """The actor net of a PPO zip (eval mode), after checking its feature layout; nothing in the file runs."""
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
    try:
        env = make_training_env(config)
    except (ValueError, TypeError) as err:
        if resume is None:
            raise
        # the resumed zip's stored environment settings (env_kwargs) do not fit this version's environment
        raise _zip_fail(Path(resume), f"its train_config does not build the environment ({_first_line(err)})") from None
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
