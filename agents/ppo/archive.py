"""Reading a PPO zip written by :mod:`agents.ppo.train` without running anything stored in it.

:func:`read_ppo_config` reads the stored :class:`~agents.ppo.config.PPOConfig`,
:func:`load_ppo` rebuilds the model (to predict or to continue training) and
:func:`load_ppo_actor` returns its actor net; every unusable file is one
:class:`~agents.checkpoint.CheckpointError` line naming it (:func:`zip_failure`).
"""

from __future__ import annotations

import dataclasses
import io
import json
import pickle
import warnings
import zipfile
from pathlib import Path
from typing import Any

import torch

from agents.checkpoint import CheckpointError
from agents.network import CorrespondenceNet
from agents.ppo.config import PPOConfig, build_model
from vo_gym.features import N_FEATURES, check_feature_layout

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
MAX_ROLLOUT_VALUES = 1 << 28
"""The most observation values a stored config's rollout buffer may hold (``n_steps x n_envs x
n_correspondences x (features + mask)``, 1 GiB of float32), which rebuilding the model allocates: the
shipped model's config (2 environments x 256 steps x N 100) holds 768 000."""
# Plain counters of ``data`` restored on load (everything else is rebuilt from the config).
ZIP_COUNTERS = ("num_timesteps", "_n_updates", "_episode_num")


def zip_failure(path: Path, what: str) -> CheckpointError:
    return CheckpointError(f"PPO model {path}: {what}")


def first_line(err: BaseException) -> str:
    return (str(err).strip().splitlines() or [type(err).__name__])[0][:160]


def _read_zip(path: str | Path, need_optimizer: bool) -> tuple[Path, dict[str, Any], dict[str, bytes]]:
    """``(path, data, members)``: the JSON ``data`` (plain values; serialized entries left as they are)
    and the raw bytes of the weight members (the optimizer's where present; required with ``need_optimizer``)."""
    path = Path(path)
    if not path.is_file():
        if path.exists():
            raise zip_failure(path, "is not a file")
        raise FileNotFoundError(f"no PPO model at {path}")
    try:
        if path.stat().st_size == 0:
            raise zip_failure(path, "is empty")
        with zipfile.ZipFile(path) as archive:
            infos = {info.filename: info for info in archive.infolist()}
            if ZIP_DATA not in infos:
                raise zip_failure(path, f"is a zip archive but not a stable-baselines3 model (no {ZIP_DATA!r} entry)")
            wanted = [ZIP_DATA, ZIP_POLICY] + ([ZIP_OPTIMIZER] if need_optimizer or ZIP_OPTIMIZER in infos else [])
            for name in wanted[1:]:
                if name not in infos:
                    raise zip_failure(path, f"holds no {name!r} entry (the {'policy weights' if name == ZIP_POLICY else 'optimizer state'})")
            for name in wanted:
                if infos[name].file_size > MAX_ZIP_MEMBER_BYTES:
                    raise zip_failure(path, f"its {name!r} entry is {infos[name].file_size} bytes, more than a model holds")
            members = {name: archive.read(name) for name in wanted}
    except CheckpointError:
        raise
    except zipfile.BadZipFile as err:
        text = str(err)
        if "File is not a zip file" in text or not zipfile.is_zipfile(path):
            raise zip_failure(path, "is not a zip archive (not a stable-baselines3 model, or truncated)") from None
        raise zip_failure(path, f"is a corrupt zip archive ({first_line(err)})") from None
    except (OSError, EOFError, ValueError, NotImplementedError, RuntimeError) as err:  # unreadable, truncated, bad compression
        raise zip_failure(path, f"cannot be read as a zip archive ({type(err).__name__}: {first_line(err)})") from None
    try:
        data = json.loads(members.pop(ZIP_DATA).decode("utf-8"))
    except (ValueError, RecursionError) as err:  # JSONDecodeError and UnicodeDecodeError are ValueErrors
        raise zip_failure(path, f"its {ZIP_DATA!r} entry is not JSON ({first_line(err)})") from None
    if not isinstance(data, dict):
        raise zip_failure(path, f"its {ZIP_DATA!r} entry must be a JSON object, got {type(data).__name__}")
    return path, data, members


def _zip_config(path: Path, data: dict[str, Any]) -> tuple[PPOConfig, dict[str, Any]]:
    """The :class:`PPOConfig` and the stored ``train_config`` of a zip's ``data`` (plain JSON only)."""
    kwargs = data.get("policy_kwargs")
    stored = kwargs.get("train_config") if isinstance(kwargs, dict) else None
    if not isinstance(stored, dict) or not stored or ":serialized:" in stored:
        raise zip_failure(path, "is an SB3 model but not a vo-gym PPO one (no plain train_config in its policy_kwargs)")
    try:
        check_feature_layout(stored.get("feature_names", ()), stored.get("feature_layout_version", -1))
    except (ValueError, TypeError) as err:
        raise CheckpointError(f"PPO model {path} was trained on another feature layout: {first_line(err)}") from None
    try:
        config = PPOConfig.from_dict(stored)
    except (ValueError, TypeError, KeyError) as err:
        raise zip_failure(path, f"its train_config is not a valid PPO config ({first_line(err)})") from None
    _check_stored_env_id(path, config.env_id)
    _check_model_size(path, config)
    return config, stored


def _check_model_size(path: Path, config: PPOConfig) -> None:
    """Refuse a stored config whose rollout buffer would be larger than anything trained here
    (:data:`MAX_ROLLOUT_VALUES`), before :func:`build_model` allocates it. The policy's sizes were
    checked when the config was built (:class:`PPOConfig` holds them within
    :data:`agents.network_size.MAX_NETWORK_SIZE` and :data:`agents.network_size.MAX_NETWORK_PARAMETERS`)."""
    values = config.n_steps * config.n_envs * config.n_correspondences * (N_FEATURES + 1)
    if values > MAX_ROLLOUT_VALUES:
        raise zip_failure(path, f"its train_config's rollout (n_steps {config.n_steps} x n_envs {config.n_envs} x "
                                f"n_correspondences {config.n_correspondences}) holds {values:,} values, more than "
                                f"{MAX_ROLLOUT_VALUES:,}")


def _check_stored_env_id(path: Path, env_id: Any) -> None:
    """Only an id already registered: gymnasium imports the module of a ``"module:Env"`` id, which
    would let a file choose code to import."""
    import gymnasium as gym

    import vo_gym  # noqa: F401  (registers the ids)

    if not isinstance(env_id, str) or ":" in env_id or env_id not in gym.registry:
        raise zip_failure(path, f"its train_config names env_id {env_id!r}, not a registered environment")


def _zip_tensors(path: Path, name: str, raw: bytes) -> Any:
    """``torch.load(weights_only=True)`` of one member: tensors and plain data, nothing run."""
    try:
        with warnings.catch_warnings():  # torch warns about odd pickle protocols: the error below says it in one line
            warnings.simplefilter("ignore")
            return torch.load(io.BytesIO(raw), map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as err:
        if "global" in str(err).lower() or "Unsupported class" in str(err):
            raise zip_failure(path, f"its {name!r} entry refused: it holds Python objects other than tensors and "
                                  "plain data, which could run code when unpickled (nothing was run)") from None
        detail = "pickle opcodes outside torch's weights-only subset" if "Unsupported operand" in str(err) \
            else first_line(err)
        raise zip_failure(path, f"its {name!r} entry is not a torch file the weights-only loader reads ({detail}; "
                              "nothing was run)") from None
    except Exception as err:  # noqa: BLE001 - weights_only parsing of untrusted bytes: any failure is one line
        raise zip_failure(path, f"its {name!r} entry is not a readable torch file "
                              f"({type(err).__name__}: {first_line(err)})") from None


def _plain_count(path: Path, data: dict[str, Any], key: str) -> int:
    value = data.get(key, 0)
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise zip_failure(path, f"its {key!r} must be an integer >= 0, got {value!r}")
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
        raise zip_failure(path, f"its 'seed' must be an integer or null, got {seed!r}")
    counters = {key: _plain_count(path, data, key) for key in ZIP_COUNTERS}
    policy_state = _zip_tensors(path, ZIP_POLICY, members[ZIP_POLICY])
    if not isinstance(policy_state, dict) or not all(
            isinstance(k, str) and isinstance(v, torch.Tensor) for k, v in policy_state.items()):
        raise zip_failure(path, f"its {ZIP_POLICY!r} entry must map parameter names to tensors")
    optimizer_state = None
    if ZIP_OPTIMIZER in members:
        optimizer_state = _zip_tensors(path, ZIP_OPTIMIZER, members[ZIP_OPTIMIZER])
        if not isinstance(optimizer_state, dict):
            raise zip_failure(path, f"its {ZIP_OPTIMIZER!r} entry must be an optimizer state dict")

    model = build_model(dataclasses.replace(config, seed=seed), env, setup=False)
    if env is None:  # predicting only: the spaces of the environment the model was trained on
        import gymnasium as gym

        try:
            probe = gym.make(config.env_id, **config.train_env_kwargs())
        except (ValueError, TypeError) as err:
            raise zip_failure(path, f"its train_config does not build the environment ({first_line(err)})") from None
        model.observation_space, model.action_space, model.n_envs = probe.observation_space, probe.action_space, 1
        probe.close()
    # What SB3's own loader does after building the object without a model (``_init_setup_model=False``).
    model._setup_model()
    try:
        model.policy.load_state_dict(policy_state)
    except RuntimeError as err:
        lines = [ln.strip() for ln in str(err).splitlines() if ln.strip()]
        detail = lines[1] if len(lines) > 1 else (lines[0] if lines else "")
        raise zip_failure(path, f"its policy weights do not fit the policy its train_config declares ({detail[:200]})") from None
    if optimizer_state is not None:
        try:
            model.policy.optimizer.load_state_dict(optimizer_state)
        except (ValueError, KeyError, TypeError, RuntimeError, IndexError) as err:
            raise zip_failure(path, f"its optimizer state does not fit the policy ({type(err).__name__}: "
                                  f"{first_line(err)})") from None
    for key, value in counters.items():
        setattr(model, key, value)
    return model


def load_ppo_actor(path: str | Path) -> CorrespondenceNet:
    """The actor net of a PPO zip (eval mode), after checking its feature layout; nothing in the file runs."""
    return load_ppo(path).policy.action_net.eval()


