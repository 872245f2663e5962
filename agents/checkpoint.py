"""Checkpoints of learned samplers: weights plus the config and feature layout they need.

Loading never runs code from the file: ``torch.load(..., weights_only=True)`` unpickles only
tensors and plain data (dicts, lists, strings, numbers), and refuses anything else before it
is built. Every way a file can be unusable (unreadable, empty, truncated, not a torch file, a
foreign payload, missing keys, an entry of the wrong type, a network larger than
:data:`MAX_NETWORK_PARAMETERS`, weights that do not fit the network it declares, weights that
are not finite, another feature layout) raises :class:`CheckpointError`, one line naming the file,
the entry and its value; a checkpoint from another feature layout is refused because a network
fed columns in a different meaning would still run and silently sample nonsense.

Everything is checked before a network is built (:func:`check_network_sizes`,
:func:`check_parameter_count`, :func:`check_state_dict`): the parameter count comes from the
declared sizes by arithmetic and every weight's shape from those sizes, so a file that declares
a huge network is refused without allocating it, and one whose tensors contradict its sizes or
hold NaN or infinite values never reaches a caller (where it would fail far from the file, or
sample nonsense). :mod:`agents.adaptive.checkpoint` checks in-frame checkpoints with the same functions.

The samplers shipped with the package are found by name through ``importlib.resources``, from
any directory and any kind of install: :func:`load_sampler`, :func:`shipped_checkpoint`. Two kinds
ship: one-shot samplers (:data:`SHIPPED_SAMPLERS`, this module's format: priors for a whole frame,
:class:`LearnedPolicy`) and in-frame samplers (:data:`SHIPPED_IN_FRAME_SAMPLERS`,
:mod:`agents.adaptive.checkpoint`'s format: priors batch by batch and a stop,
:class:`agents.adaptive.policy.AdaptiveSamplerPolicy`). :func:`load_sampler` loads the one-shot ones and
names the loader of the others; :func:`agents.load_sampler` loads either and
:class:`agents.LearnedEstimator` runs either on a user's own matches.
"""

from __future__ import annotations

import contextlib
import importlib.resources
import numbers
import os
import pickle
import struct
import zipfile
from pathlib import Path
from typing import Any, Iterator

import numpy as np
import torch

from agents.catalog import IN_FRAME, IN_FRAME_SAMPLERS, ONE_SHOT, SHIPPED_FOLDER, SHIPPED_PACKAGE, SHIPPED_SAMPLERS
from agents.network import CorrespondenceNet, correspondence_net_shapes
from agents.network_size import MAX_NETWORK_PARAMETERS, MAX_NETWORK_SIZE, correspondence_net_parameters
from stereovo.options import value_repr
from vo_gym.features import FEATURE_LAYOUT_VERSION, FEATURE_NAMES, check_feature_layout

FORMAT_VERSION = 1


def save_checkpoint(path: str | Path, net: CorrespondenceNet, config: dict[str, Any], state: dict[str, Any] | None = None) -> Path:
    """Write ``net`` with its architecture, the training ``config`` and optional trainer ``state``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    payload = {
        "format_version": FORMAT_VERSION,
        "network": net.config(),
        "state_dict": {k: v.detach().cpu() for k, v in net.state_dict().items()},
        "feature_names": list(FEATURE_NAMES),
        "feature_layout_version": FEATURE_LAYOUT_VERSION,
        "config": config,
        "trainer_state": state or {},
    }
    tmp = path.with_suffix(path.suffix + ".tmp")
    torch.save(payload, tmp)
    tmp.replace(path)  # never leave a half-written checkpoint behind
    return path


REQUIRED_KEYS = ("format_version", "network", "state_dict", "feature_names", "feature_layout_version")
NETWORK_KEYS = ("n_features", "width", "blocks")
SHIPPED_IN_FRAME_SAMPLERS = IN_FRAME_SAMPLERS
"""Names of the in-frame samplers shipped inside the package (:mod:`agents.adaptive.checkpoint`'s format)."""
SAMPLER_KINDS: tuple[str, ...] = (ONE_SHOT, IN_FRAME)
IN_FRAME_FORMAT = "vo-gym adaptive sampler v1"
"""The ``format`` entry of an in-frame sampler's checkpoint (:func:`agents.adaptive.checkpoint.save_adaptive`)."""


class CheckpointError(ValueError):
    """A checkpoint file that cannot be used; the one-line message names the file and what is wrong."""


def _fail(path: Path, what: str) -> CheckpointError:
    return CheckpointError(f"checkpoint {path}: {what}")


def _torch_load(path: Path) -> Any:
    """``torch.load`` restricted to tensors and plain data; every failure as one CheckpointError line."""
    try:
        size = path.stat().st_size
    except OSError as err:
        raise _fail(path, f"cannot be read ({err.strerror or err})") from None
    if size == 0:
        raise _fail(path, "is empty")
    try:
        return torch.load(path, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as err:
        text = str(err)
        # The restricted unpickler names a global (class or function) it will not build: code refused.
        # Anything else it cannot parse ("Unsupported operand", bad opcodes) is simply not a checkpoint.
        if "global" in text.lower() or "Unsupported class" in text:
            raise _fail(path, "refused: it holds Python objects other than tensors and plain data, "
                              "which could run code when unpickled (nothing was run)") from None
        raise _fail(path, "is not a torch checkpoint (not a pickle or zip archive torch can read)") from None
    except struct.error:  # a pickle opcode whose argument the file lacks (e.g. a short text file)
        raise _fail(path, "is not a torch checkpoint (not a pickle or zip archive torch can read)") from None
    except (EOFError, zipfile.BadZipFile):
        raise _fail(path, "is truncated or corrupt (it ends before the data does)") from None
    except (RuntimeError, OSError, ValueError, KeyError, IndexError, TypeError, AttributeError,
            UnicodeDecodeError, MemoryError, OverflowError) as err:
        first = (str(err).strip().splitlines() or [type(err).__name__])[0]
        if "zip" in first.lower() or "inline_container" in first or "central directory" in first:
            if zipfile.is_zipfile(path):  # a whole archive, but not torch's layout
                raise _fail(path, "is a zip archive but not a torch checkpoint") from None
            raise _fail(path, "is truncated or corrupt (its zip archive is incomplete)") from None
        raise _fail(path, f"is not a torch checkpoint torch can read ({type(err).__name__}: {first[:160]})") from None


def read_payload(path: str | os.PathLike) -> Any:
    """The unpickled content of a checkpoint file, tensors and plain data only (nothing in it runs).

    Raises:
        FileNotFoundError: no such file.
        CheckpointError: a directory, or a file torch cannot read as data (one line naming it).
    """
    path = Path(path)
    if not path.is_file():
        if path.exists():
            raise _fail(path, "is not a file")
        raise FileNotFoundError(f"no checkpoint at {path}")
    return _torch_load(path)


def shown(value: Any, limit: int = 80) -> str:
    """A file's entry for a one-line message: :func:`stereovo.options.value_repr` cut to ``limit``
    characters (a huge integer written by its magnitude)."""
    return value_repr(value, limit)


def check_names(path: Path, key: str, names: Any) -> tuple[str, ...]:
    """A checkpoint's list of feature names (``key``): a list or tuple of strings."""
    if not isinstance(names, (list, tuple)) or not all(isinstance(n, str) for n in names):
        raise _fail(path, f"its {key!r} must be a list of strings, got {shown(names)}")
    return tuple(names)


def check_network_sizes(path: Path, network: Any, defaults: dict[str, Any], required: tuple[str, ...] = (),
                        where: str = "network", extra: tuple[str, ...] = ()) -> dict[str, Any]:
    """The declared sizes ``network`` of a network with keywords ``defaults`` (their defaults), each
    an integer in [1, :data:`MAX_NETWORK_SIZE`]; returns them with the defaults filled in.

    ``required`` keys must be present; ``extra`` keys are allowed and left to the caller (not sizes).
    ``where`` names the entry in messages (``"network"``, ``"network prior"``).
    """
    known = tuple(defaults) + tuple(extra)
    if not isinstance(network, dict):
        raise _fail(path, f"its {where!r} entry must be a dict of {', '.join(known)}, got {type(network).__name__}")
    unknown = sorted(shown(k, 40).strip("'") for k in network if k not in known)
    if unknown:
        raise _fail(path, f"unknown {where} keyword(s) {', '.join(unknown)} (known: {', '.join(known)})")
    missing = [k for k in required if k not in network]
    if missing:
        raise _fail(path, f"its {where!r} entry lacks {', '.join(missing)}")
    sizes = {**defaults, **{k: v for k, v in network.items() if k not in extra}}
    for key, value in sizes.items():
        if not isinstance(value, numbers.Integral) or isinstance(value, bool) or not 1 <= value <= MAX_NETWORK_SIZE:
            raise _fail(path, f"{where} {key} must be an integer in [1, {MAX_NETWORK_SIZE}], got {shown(value)}")
    return {k: int(v) for k, v in sizes.items()}


def check_parameter_count(path: Path, count: int, network: Any) -> None:
    """Refuse networks declaring more than :data:`MAX_NETWORK_PARAMETERS` parameters (``count``,
    computed from the declared sizes), before anything is built."""
    if count > MAX_NETWORK_PARAMETERS:
        raise _fail(path, f"its 'network' {network!r} declares {count:,} parameters, more than the "
                          f"{MAX_NETWORK_PARAMETERS:,} a sampler checkpoint may hold (refused before building it)")


def check_state_dict(path: Path, state: Any, shapes: dict[str, tuple[int, ...]], network: Any) -> None:
    """The ``state_dict`` against the parameter ``shapes`` the declared ``network`` implies: the same
    names, dense floating-point tensors of those shapes, every value finite (as float32, the
    networks' type). Checked before a network is built, so nothing large is allocated."""
    if not isinstance(state, dict):
        raise _fail(path, f"its 'state_dict' must map parameter names to tensors, got {type(state).__name__}")
    for key, value in state.items():
        if not isinstance(key, str) or not isinstance(value, torch.Tensor):
            raise _fail(path, f"its 'state_dict' must map parameter names to tensors, got {shown(key, 40)}: {type(value).__name__}")
    missing = [k for k in shapes if k not in state]
    unexpected = [k for k in state if k not in shapes]
    if missing or unexpected:
        parts = ([f"missing {', '.join(shown(k, 40) for k in missing[:3])}{' ...' if len(missing) > 3 else ''}"] if missing else []) + \
                ([f"unexpected {', '.join(shown(k, 40) for k in unexpected[:3])}{' ...' if len(unexpected) > 3 else ''}"]
                 if unexpected else [])
        raise _fail(path, f"its weights do not fit the network it declares {network!r} ({'; '.join(parts)})")
    for key, shape in shapes.items():
        tensor = state[key]
        if tensor.layout != torch.strided or not tensor.is_floating_point():
            raise _fail(path, f"its weight state_dict[{key!r}] must be a dense floating-point tensor, "
                              f"got {tensor.dtype} ({tensor.layout})")
        if tuple(tensor.shape) != shape:
            raise _fail(path, f"its weights do not fit the network it declares {network!r} "
                              f"(state_dict[{key!r}] has shape {tuple(tensor.shape)}, the network needs {shape})")
    for key in shapes:
        finite = torch.isfinite(state[key].to(torch.float32))
        if not bool(finite.all()):
            bad = int((~finite).sum())
            raise _fail(path, f"its weight state_dict[{key!r}] holds {bad} NaN or infinite value(s) "
                              f"(of {finite.numel()}); a network with them scores nothing")


def _check_payload(path: Path, payload: Any) -> dict[str, int]:
    """The payload's schema: what :func:`save_checkpoint` writes; returns the network's sizes.

    Every entry's type and value, the network's total size and every weight's shape and values,
    all before a network is built.
    """
    if not isinstance(payload, dict):
        raise _fail(path, f"is not a vo-gym sampler checkpoint (holds a {type(payload).__name__}, not a dict)")
    missing = [k for k in REQUIRED_KEYS if k not in payload]
    if missing:
        raise _fail(path, f"is not a vo-gym sampler checkpoint (missing key(s) {', '.join(missing)})")
    version = payload["format_version"]
    if not isinstance(version, numbers.Integral) or isinstance(version, bool) or version != FORMAT_VERSION:
        raise _fail(path, f"its 'format_version' is {shown(version)}; this version reads format {FORMAT_VERSION}")
    network = payload["network"]
    sizes = check_network_sizes(path, network, {"n_features": None, "width": 64, "blocks": 3}, required=("n_features",))
    names = check_names(path, "feature_names", payload["feature_names"])
    layout = payload["feature_layout_version"]
    if not isinstance(layout, numbers.Integral) or isinstance(layout, bool):
        raise _fail(path, f"its 'feature_layout_version' must be an integer, got {shown(layout)}")
    try:
        check_feature_layout(names, layout)
    except ValueError as err:
        raise CheckpointError(f"checkpoint {path} was trained on another feature layout: {err}") from None
    if sizes["n_features"] != len(names):
        raise _fail(path, f"its network n_features is {sizes['n_features']}, but its 'feature_names' lists {len(names)}")
    for key in ("config", "trainer_state"):
        if key in payload and not isinstance(payload[key], dict):
            raise _fail(path, f"its {key!r} entry must be a dict, got {type(payload[key]).__name__}")
    check_parameter_count(path, correspondence_net_parameters(**sizes), network)
    check_state_dict(path, payload["state_dict"], correspondence_net_shapes(**sizes), network)
    return sizes


def load_checkpoint(path: str | os.PathLike) -> tuple[CorrespondenceNet, dict[str, Any]]:
    """Load a checkpoint; returns the network (eval mode) and the whole payload.

    Nothing in the file is run (``weights_only=True``), and the network is built only once the
    file passed every check (:func:`_check_payload`): its size within :data:`MAX_NETWORK_PARAMETERS`,
    every weight of the shape the declared sizes imply, and finite.

    Raises:
        FileNotFoundError: no such file.
        CheckpointError: (a ``ValueError``) the file is unreadable, not a vo-gym checkpoint, an
            entry has the wrong type, its network is too large, its weights do not fit the network
            it declares or are not finite, or its feature layout differs from this version's; one
            line naming the file and what is wrong.
    """
    path = Path(path)
    payload = read_payload(path)
    sizes = _check_payload(path, payload)  # the feature layout included
    net = CorrespondenceNet(**sizes)
    try:
        net.load_state_dict(payload["state_dict"])
    except RuntimeError as err:
        lines = [ln.strip() for ln in str(err).splitlines() if ln.strip()]
        detail = lines[1] if len(lines) > 1 else (lines[0] if lines else "")
        raise _fail(path, f"its weights do not fit the network it declares {payload['network']} ({detail[:200]})") from None
    net.eval()
    return net, payload


@contextlib.contextmanager
def shipped_checkpoint(name: str) -> Iterator[Path]:
    """A file path of the shipped sampler ``name`` (one of :data:`SHIPPED_SAMPLERS` or
    :data:`SHIPPED_IN_FRAME_SAMPLERS`), for a ``with`` block.

    Found with ``importlib.resources`` inside the installed ``agents`` package, so it works from
    any directory, editable or not (a zipped install gets a temporary copy for the block).

    Raises:
        ValueError: an unknown name (listing the shipped ones).
        FileNotFoundError: the install lacks the file (a build that left out the package data).
    """
    if name not in SHIPPED_SAMPLERS + SHIPPED_IN_FRAME_SAMPLERS:
        raise ValueError(f"unknown shipped sampler {name!r}; shipped: {', '.join(SHIPPED_SAMPLERS + SHIPPED_IN_FRAME_SAMPLERS)}")
    resource = importlib.resources.files(SHIPPED_PACKAGE).joinpath(SHIPPED_FOLDER, f"{name}.pt")
    if not resource.is_file():
        raise FileNotFoundError(f"shipped sampler {name!r} is missing from this install ({resource})")
    with importlib.resources.as_file(resource) as file:
        yield Path(file)


def sampler_kind(payload: Any) -> str | None:
    """:data:`ONE_SHOT` or :data:`IN_FRAME` for a checkpoint payload of either format, else None."""
    if not isinstance(payload, dict):
        return None
    if payload.get("format") == IN_FRAME_FORMAT:
        return IN_FRAME
    if "format_version" in payload:
        return ONE_SHOT
    return None


def resolve_sampler(name_or_path: str | os.PathLike) -> tuple[str, str, Path | None]:
    """``(kind, name, path)`` of a shipped sampler name (``path`` None) or a checkpoint file of either kind.

    A one-shot file is checked whole here (its schema, network size, weight shapes and finiteness:
    :func:`_check_payload`; no network is built); an in-frame file only by its kind, and whole by
    :func:`agents.adaptive.checkpoint.check_adaptive_payload` (that module imports this one), which
    ``vo-gym train`` calls before it starts anything.

    Raises:
        ValueError: an unknown name; CheckpointError: an unusable file of either format, or of
        neither (naming what is wrong); FileNotFoundError: no such file.
    """
    text = os.fspath(name_or_path)
    if text in SHIPPED_SAMPLERS:
        return ONE_SHOT, text, None
    if text in SHIPPED_IN_FRAME_SAMPLERS:
        return IN_FRAME, text, None
    path = Path(text).expanduser()
    if not path.exists() and path.suffix != ".pt" and os.sep not in text:
        shipped = ", ".join(SHIPPED_SAMPLERS + SHIPPED_IN_FRAME_SAMPLERS)
        raise ValueError(f"unknown sampler {text!r}: not a shipped one ({shipped}) and not a checkpoint file")
    payload = read_payload(path)
    kind = sampler_kind(payload)
    if kind != IN_FRAME:  # an in-frame file is checked whole by agents.adaptive.checkpoint (which imports this module)
        _check_payload(path, payload)  # a one-shot one here; of neither format: names what is wrong
    return kind, path.stem, path


def load_sampler(name_or_path: str | os.PathLike, temperature: float = 1.0) -> "LearnedPolicy":
    """A one-shot learned sampler as a policy: a shipped one by name (:data:`SHIPPED_SAMPLERS`) or a ``.pt`` path.

    Example: ``policy = load_sampler("ngransac-supervised"); logits = policy.act(observation)``;
    ``weights = policy.priors(prev, curr, camera, scores)`` on raw matches. In-frame samplers
    (:data:`SHIPPED_IN_FRAME_SAMPLERS`) load with :func:`agents.load_sampler` (either kind) or
    :func:`agents.adaptive.checkpoint.load_adaptive`; :class:`agents.LearnedEstimator` runs either.

    Raises:
        ValueError: an unknown name, or an in-frame sampler (naming the loader that takes it);
        CheckpointError: an unusable file; FileNotFoundError: no such file.
    """
    kind, name, path = resolve_sampler(name_or_path)
    if kind == IN_FRAME:
        raise ValueError(f"sampler {os.fspath(name_or_path)!r} is an in-frame sampler: load it with agents.load_sampler "
                         "(either kind) or agents.adaptive.checkpoint.load_adaptive, or run it with agents.LearnedEstimator")
    return resolved_policy(name, path, temperature)


def resolved_policy(name: str, path: Path | None, temperature: float = 1.0) -> "LearnedPolicy":
    """The policy of a one-shot sampler :func:`resolve_sampler` found: shipped ``name`` (``path``
    None) or the checkpoint at ``path``."""
    if path is None:
        with shipped_checkpoint(name) as shipped:
            net, _ = load_checkpoint(shipped)
    else:
        net, _ = load_checkpoint(path)
    return LearnedPolicy(net, name, temperature)


class LearnedPolicy:
    """A trained one-shot network as a policy: observation ``{"features", "mask"}`` in, logits out.

    ``act`` reads the environment's observation (``features (N, F)`` or ``(B, N, F)`` of
    :data:`vo_gym.features.FEATURE_NAMES`, ``mask`` ``(N,)`` or ``(B, N)``); ``priors`` goes from
    raw stereo matches to the guided-sampling weights ``estimate_motion(..., priors=)`` takes.
    """

    kind = ONE_SHOT

    def __init__(self, net: CorrespondenceNet, name: str = "learned", temperature: float = 1.0) -> None:
        if not (isinstance(temperature, numbers.Real) and np.isfinite(temperature) and temperature > 0):
            raise ValueError(f"temperature must be a finite number > 0, got {temperature!r}")
        self.net = net.eval()
        self.name = name
        self.temperature = temperature

    @classmethod
    def from_checkpoint(cls, path: str | Path, name: str | None = None) -> "LearnedPolicy":
        net, _ = load_checkpoint(path)
        return cls(net, name or Path(path).stem)

    @torch.no_grad()
    def act(self, observation: dict) -> np.ndarray:
        """Logits ``(N,)`` or ``(B, N)`` float32, centred on the valid slots and clipped to
        ``[-LOGIT_BOUND, LOGIT_BOUND]``; padded slots ``-LOGIT_BOUND``.

        Raises:
            ValueError: ``observation`` is not a dict with ``features`` and ``mask`` of matching shapes.
        """
        if not isinstance(observation, dict) or "features" not in observation or "mask" not in observation:
            raise ValueError(
                f"{self.name}: act() takes the observation dict {{'features': (N, {self.net.n_features}), 'mask': (N,)}}, "
                f"got {type(observation).__name__}; for raw matches use priors(prev, curr, camera, scores)"
            )
        features = torch.as_tensor(np.asarray(observation["features"], dtype=np.float32))
        mask = torch.as_tensor(np.asarray(observation["mask"]).astype(bool))
        if features.ndim not in (2, 3) or tuple(mask.shape) != tuple(features.shape[:-1]):
            raise ValueError(f"{self.name}: observation features must be (N, F) or (B, N, F) with a mask of the "
                             f"leading shape, got {tuple(features.shape)} and {tuple(mask.shape)}")
        single = features.ndim == 2
        if single:
            features, mask = features[None], mask[None]
        logits = self.net(features, mask) / self.temperature
        # Centre on the valid slots so the action stays inside the env's bounded Box.
        valid = mask.float()
        mean = (logits * valid).sum(-1, keepdim=True) / valid.sum(-1, keepdim=True).clamp_min(1)
        from agents.policies import LOGIT_BOUND

        out = torch.where(mask, (logits - mean).clamp(-LOGIT_BOUND, LOGIT_BOUND), torch.tensor(-LOGIT_BOUND))
        out = out.numpy().astype(np.float32)
        return out[0] if single else out

    def weights(self, features: np.ndarray, mask: np.ndarray) -> np.ndarray:
        """Guided-sampling weights ``(N,)`` float64 in (0, 1] (``exp`` of :meth:`act`'s logits,
        max-normalised) from ``features (N, F)``; 0 where ``mask`` is 0."""
        logits = np.asarray(self.act({"features": features, "mask": mask}), dtype=np.float64)
        valid = np.asarray(mask, dtype=bool)
        out = np.zeros(valid.shape[0])
        if valid.any():
            out[valid] = np.exp(logits[valid] - logits[valid].max())
        return out

    def priors(self, prev: np.ndarray, curr: np.ndarray, camera, scores: np.ndarray | None = None,
               previous_motion: tuple[np.ndarray, np.ndarray] | None = None, noise_sigma: float = 0.5) -> np.ndarray:
        """The sampler's guided-sampling weights ``(N,)`` for N stereo matches, ready for
        ``stereovo.estimate_motion(prev, curr, camera, method="msac", priors=...)``.

        Args:
            prev, curr: ``(N, 4)`` measurements ``(uL, vL, uR, vR)`` in pixels at k-1 and k.
            camera: the :class:`stereovo.StereoCamera`.
            scores: ``(N,)`` match scores in [0, 1], higher = better; None: unknown, every row gets
                the uninformative score (:mod:`agents.matches`, as :class:`agents.LearnedEstimator`).
            previous_motion: ``(R (3, 3), t (3,) m)`` estimated for the previous frame pair
                (``x_k = R x_{k-1} + t``), the constant-velocity feature; None if unknown.
            noise_sigma: the pixel noise (px) the features assume.

        Rows without depth get weight 0 (the estimator never samples them).

        Raises:
            ValueError: malformed input (as :func:`vo_gym.features.compute_features`).
        """
        from agents.matches import match_features
        from vo_gym.features import usable_rows

        features = match_features(prev, curr, camera, scores, noise_sigma, previous_motion)
        return self.weights(features, usable_rows(features))


def export_checkpoint(source: str | Path, destination: str | Path) -> Path:
    """Copy a checkpoint without its optimizer state: what ships needs weights, config and layout only."""
    net, payload = load_checkpoint(source)
    history = payload.get("trainer_state", {}).get("history", [])
    return save_checkpoint(destination, net, payload["config"], {"history": history})
