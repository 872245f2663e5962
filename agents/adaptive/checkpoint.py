"""The in-frame sampler's checkpoints: writing, checking and loading them.

:func:`save_adaptive` writes the weights, the network's sizes, the feature layout and the training
config (format :data:`FORMAT`); :func:`load_adaptive` reads a file or a shipped name
(``agents/checkpoints/adaptive-*.pt``) with ``weights_only`` and builds the network only once
:func:`check_adaptive_payload` has checked the whole file with the one-shot checkpoints' functions
(:mod:`agents.checkpoint`).
"""

from __future__ import annotations

import json
from importlib import resources
from pathlib import Path
from typing import Any

import torch

from agents.adaptive.network import AdaptiveSamplerNet
from agents.checkpoint import (
    IN_FRAME_FORMAT,
    CheckpointError,
    check_names,
    check_network_sizes,
    check_parameter_count,
    check_state_dict,
    read_payload,
    shown,
)
from vo_gym.adaptive_env import ADAPTIVE_FEATURE_NAMES, GLOBAL_FEATURE_NAMES

FORMAT = IN_FRAME_FORMAT


def save_adaptive(path: str | Path, net: AdaptiveSamplerNet, config: dict[str, Any], log: list | None = None) -> Path:
    """Weights, architecture, feature layout and training config; loadable with ``weights_only``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    payload = {
        "format": FORMAT, "network": net.config(), "feature_names": list(ADAPTIVE_FEATURE_NAMES),
        "global_names": list(GLOBAL_FEATURE_NAMES), "config": json.loads(json.dumps(config)),
        "log": json.loads(json.dumps(log or [])),
        "state_dict": {k: v.detach().cpu() for k, v in net.state_dict().items()},
    }
    tmp = path.with_suffix(path.suffix + ".tmp")
    torch.save(payload, tmp)
    tmp.replace(path)
    return path


def shipped_adaptive_path(name: str) -> Path:
    """Path of a shipped checkpoint ``agents/checkpoints/NAME.pt`` (``NAME`` starts with ``adaptive-``)."""
    return Path(str(resources.files("agents").joinpath("checkpoints", f"{name}.pt")))


NETWORK_SIZES = {"n_features": len(ADAPTIVE_FEATURE_NAMES), "n_globals": len(GLOBAL_FEATURE_NAMES), "width": 48, "blocks": 3}
"""The sizes of :class:`AdaptiveSamplerNet` a checkpoint declares in ``network``, with the defaults of
a checkpoint that leaves one out (as the constructor's)."""
_PRIOR_SIZES = {"n_features": None, "width": 64, "blocks": 3}


def check_adaptive_payload(path: Path, payload: Any) -> dict[str, Any]:
    """An in-frame checkpoint's schema (what :func:`save_adaptive` writes), checked before any network
    is built: the format, every entry's type, the feature layout, the network's sizes (each in
    [1, :data:`agents.network_size.MAX_NETWORK_SIZE`], all together within
    :data:`agents.network_size.MAX_NETWORK_PARAMETERS`, the prior's included) and every weight's shape
    and finiteness. Returns the keywords of :class:`~agents.adaptive.network.AdaptiveSamplerNet`.

    Raises:
        CheckpointError: one line naming the file, the entry and its value.
    """
    if not isinstance(payload, dict) or payload.get("format") != FORMAT:
        hint = " (a one-shot sampler: agents.checkpoint.load_sampler)" if isinstance(payload, dict) and "format_version" in payload else ""
        raise CheckpointError(f"checkpoint {path}: is not an adaptive-sampler checkpoint{hint}")
    for key in ("network", "feature_names", "global_names", "state_dict"):
        if key not in payload:
            raise CheckpointError(f"checkpoint {path}: is not an adaptive-sampler checkpoint (missing key {key})")
    names = check_names(path, "feature_names", payload["feature_names"])
    globals_ = check_names(path, "global_names", payload["global_names"])
    if names != ADAPTIVE_FEATURE_NAMES or globals_ != GLOBAL_FEATURE_NAMES:
        raise CheckpointError(f"checkpoint {path} was trained on another adaptive feature layout "
                              f"(feature_names {shown(list(names))}, global_names {shown(list(globals_))})")
    for key, kind in (("config", dict), ("log", list)):
        if key in payload and not isinstance(payload[key], kind):
            raise CheckpointError(f"checkpoint {path}: its {key!r} entry must be a {kind.__name__}, got {shown(payload[key])}")
    declared = payload["network"]
    sizes = check_network_sizes(path, declared, NETWORK_SIZES, extra=("prior",))
    prior = declared.get("prior")
    if prior is not None:
        from vo_gym.features import N_FEATURES

        prior = check_network_sizes(path, prior, _PRIOR_SIZES, required=("n_features",), where="network prior")
        if prior["n_features"] != N_FEATURES:
            raise CheckpointError(f"checkpoint {path}: its network prior n_features must be {N_FEATURES} "
                                  f"(the one-shot samplers' features), got {prior['n_features']}")
    for key, names_key, count in (("n_features", "feature_names", len(names)), ("n_globals", "global_names", len(globals_))):
        if sizes[key] != count:
            raise CheckpointError(f"checkpoint {path}: its network {key} is {sizes[key]}, but its {names_key!r} lists {count}")
    network = {**sizes, "prior": prior}
    check_parameter_count(path, AdaptiveSamplerNet.parameter_count(**network), declared)
    check_state_dict(path, payload["state_dict"], AdaptiveSamplerNet.parameter_shapes(**network), declared)
    return network


def load_adaptive(name_or_path: str | Path) -> tuple[AdaptiveSamplerNet, dict[str, Any]]:
    """Load by shipped name (``"adaptive-pg"``) or by path; returns the network (eval mode) and payload.

    Nothing in the file runs (``weights_only``), and the network is built only once the file passed
    :func:`check_adaptive_payload`. Every error is one line naming the file.

    Raises:
        FileNotFoundError: no such file or shipped name.
        ValueError (:class:`agents.checkpoint.CheckpointError` for an unusable file): not an
            adaptive-sampler checkpoint, an entry of the wrong type, another feature layout, a
            network too large, weights that do not fit or are not finite.
    """
    path = Path(name_or_path)
    if not path.is_file() and str(name_or_path).startswith("adaptive-"):
        path = shipped_adaptive_path(str(name_or_path))
    if not path.is_file():
        raise FileNotFoundError(f"no adaptive-sampler checkpoint {str(name_or_path)!r} (neither a file nor a shipped name)")
    payload = read_payload(path)
    network = check_adaptive_payload(path, payload)
    try:
        net = AdaptiveSamplerNet(**network)
        net.load_state_dict(payload["state_dict"])
    except (TypeError, ValueError, RuntimeError) as err:
        first = (str(err).strip().splitlines() or [type(err).__name__])[0]
        raise CheckpointError(f"checkpoint {path}: its weights do not fit the network it declares ({first[:160]})") from None
    return net.eval(), payload
