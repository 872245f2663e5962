"""Gymnasium ids of the environment, registered on ``import vo_gym``.

``gymnasium.make("vo_gym/StereoVO-v0")`` after ``import vo_gym``, or
``gymnasium.make("vo_gym:vo_gym/StereoVO-v0")`` without it (Gymnasium imports
the module first). Keyword arguments of ``make`` override the registered ones;
every one is an argument of the id's class (:class:`vo_gym.env.StereoVOEnv`,
:class:`vo_gym.adaptive_env.StereoVOAdaptiveEnv` or :class:`vo_gym.images_env.StereoVOImagesEnv`).

Worker processes that start afresh (stable-baselines3's ``SubprocVecEnv`` uses
``forkserver`` on Linux, ``spawn`` elsewhere) have not imported ``vo_gym``: give
them the module-qualified id, ``make_vec_env("vo_gym:vo_gym/StereoVO-v0", ...,
vec_env_cls=SubprocVecEnv)``. Gymnasium's own ``make_vec`` ships the spec with
its entry point and needs nothing special, with one exception: async workers of
``StereoVOImages-v0`` forked from a process that has rendered (OpenGL does not survive
``fork``) refuse to render, naming the fix, ``vector_kwargs={"context": "forkserver"}``
(or ``"spawn"``).
"""

from __future__ import annotations

from typing import Any

import gymnasium

__all__ = ["ENV_IDS", "ADAPTIVE_ENV_IDS", "IMAGE_ENV_IDS", "HARD_SETTINGS", "STEP", "IN_FRAME", "IMAGES", "OTHER",
           "env_kind", "register_envs", "registered_ids", "step_ids"]

ENTRY_POINT = "vo_gym.env:StereoVOEnv"

HARD_SETTINGS: dict[str, Any] = {
    "outlier_ratio": (0.6, 0.85),
    "outlier_mix": (0.4, 0.2, 0.4),
    "score_auc": 0.6,
}
"""The benchmark setting of the *Hard* ids: high contamination drawn per frame from
[0.6, 0.85], 40 % of the outliers on a moving object (a consensus of its own), and
weak match scores (ROC AUC 0.6)."""

ENV_IDS: dict[str, dict[str, Any]] = {
    # Guided sampling: the action is per-correspondence logits.
    "vo_gym/StereoVO-v0": {"sampling": "guided"},
    # PROSAC: the action is per-correspondence scores; their ranking is the order.
    "vo_gym/StereoVOProsac-v0": {"sampling": "prosac"},
    # Benchmarks for learned samplers.
    "vo_gym/StereoVOHard-v0": {"sampling": "guided", **HARD_SETTINGS},
    "vo_gym/StereoVOProsacHard-v0": {"sampling": "prosac", **HARD_SETTINGS},
}
"""The step environments' ids (:class:`vo_gym.env.StereoVOEnv`) and their keyword arguments;
``vo_gym.ENV_IDS`` lists every registered id (:func:`registered_ids`)."""

ADAPTIVE_ENTRY_POINT = "vo_gym.adaptive_env:StereoVOAdaptiveEnv"

ADAPTIVE_ENV_IDS: dict[str, dict[str, Any]] = {
    # In-frame adaptive sampling: one step is one batch of hypotheses, the action the next priors and a stop.
    "vo_gym/StereoVOAdaptive-v0": {},
    "vo_gym/StereoVOAdaptiveHard-v0": dict(HARD_SETTINGS),
}
"""Ids of :class:`vo_gym.adaptive_env.StereoVOAdaptiveEnv` and their keyword arguments."""


IMAGES_ENTRY_POINT = "vo_gym.images_env:StereoVOImagesEnv"

IMAGE_ENV_IDS: dict[str, dict[str, Any]] = {
    # Matches from images (rendered by default; source= a KittiOdometry or another sequence), the
    # observation layout of vo_gym/StereoVO-v0. Needs the images and render extras.
    "vo_gym/StereoVOImages-v0": {"sampling": "guided"},
}
"""Ids of :class:`vo_gym.images_env.StereoVOImagesEnv` and their keyword arguments."""


MISSING_NAMESPACE_ENTRY_POINT = "vo_gym.names:missing_namespace"


def register_envs() -> None:
    """Register every id of :data:`ENV_IDS`, :data:`ADAPTIVE_ENV_IDS` and :data:`IMAGE_ENV_IDS` (idempotent).

    Each id's bare name (``StereoVO-v0``, without ``vo_gym/``) is registered too, to an entry
    point that only raises an error naming the full id (:func:`vo_gym.names.missing_namespace`):
    Gymnasium suggests near names only within one namespace.
    """
    for ids, entry_point in ((ENV_IDS, ENTRY_POINT), (ADAPTIVE_ENV_IDS, ADAPTIVE_ENTRY_POINT),
                             (IMAGE_ENV_IDS, IMAGES_ENTRY_POINT)):
        for env_id, kwargs in ids.items():
            if env_id not in gymnasium.registry:
                gymnasium.register(id=env_id, entry_point=entry_point, kwargs=dict(kwargs))
    for env_id in registered_ids():
        bare = env_id.partition("/")[2]
        if bare not in gymnasium.registry:
            gymnasium.register(id=bare, entry_point=MISSING_NAMESPACE_ENTRY_POINT, kwargs={"full_id": env_id})


def registered_ids() -> tuple[str, ...]:
    """Every id registered in Gymnasium's ``vo_gym/`` namespace, sorted (whoever registered it)."""
    return tuple(sorted(env_id for env_id in gymnasium.registry if env_id.startswith("vo_gym/")))


STEP, IN_FRAME, IMAGES, OTHER = "step", "in-frame", "images", "other"
"""The kinds of registered id :func:`env_kind` tells apart."""

_KINDS = {ENTRY_POINT: STEP, ADAPTIVE_ENTRY_POINT: IN_FRAME, IMAGES_ENTRY_POINT: IMAGES}


def env_kind(env_id: str) -> str | None:
    """What the registered id ``env_id`` steps, by its entry point (the vo_gym ids registered first):
    :data:`STEP` (:class:`vo_gym.env.StereoVOEnv`: one action per frame on simulated matches, what the
    one-shot trainers and the sweeps' metric step), :data:`IN_FRAME` (the adaptive env, whose action
    also stops the search), :data:`IMAGES` (matches from images), :data:`OTHER` (any other
    entry point, e.g. a bare name or another package's id), or None when ``env_id`` is not registered."""
    register_envs()
    spec = gymnasium.registry.get(env_id) if isinstance(env_id, str) else None
    if spec is None:
        return None
    entry_point = spec.entry_point
    if not isinstance(entry_point, str):  # a class or a factory registered by hand
        entry_point = f"{getattr(entry_point, '__module__', '')}:{getattr(entry_point, '__qualname__', '')}"
    return _KINDS.get(entry_point, OTHER)


def step_ids() -> tuple[str, ...]:
    """The registered ``vo_gym/`` ids of kind :data:`STEP`, sorted (the ids a one-shot sampler trains
    and is evaluated on)."""
    return tuple(env_id for env_id in registered_ids() if env_kind(env_id) == STEP)
