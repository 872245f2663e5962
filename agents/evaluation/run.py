"""Evaluation of sampling agents side by side with classical methods, on the same held-out frames.

What ``vo-gym evaluate`` runs, reusable from Python (the success rate the PPO trainer's callback
measures is :func:`agents.rollout.success_rate`).

Protocol:

- A *setting* is one ``(epsilon, budget)`` pair of the environment
  (``outlier_ratio=epsilon``, ``budget`` hypotheses per frame, ``N``
  correspondences, match-score AUC); two sweeps share the machinery:
  (a) contamination at the fixed ``budget`` and (b) the hypothesis budget at
  ``sweep_epsilon`` (0.8).
- Episode ``i`` of every setting is the environment reset with seed
  ``seed + i``. The environment draws its trajectory and frames from the seed
  alone, never from the actions (:func:`episode_frames` reads them back), so
  every agent of a setting sees the identical frame sequence, and so do the
  classical methods: they run on those very frames through
  :mod:`stereovo.benchmark`'s :class:`~stereovo.benchmark.ClassicalEstimator`.
  Frames of one epsilon are also identical across budgets.
- Agents act through the environment (so learned and constant-velocity agents
  get their features from their own previous estimates, as in training). An
  in-frame sampler (``adaptive-pg-prior``, ...) steers the search inside a frame,
  which the per-frame environment has no action for: it runs on the episode's
  frames through :class:`agents.LearnedEstimator` (the environments' estimator
  options, its previous estimate feeding the next frame's features, as in the
  environment), at the setting's budget batch after batch and, with
  ``adaptive_agents``, under its own stop (:func:`run_in_frame_episode`).
  Classical methods run three ways: with the environment's estimator settings at
  the same fixed budget (``"<method> (fixed)"``, the like-for-like comparison);
  with their own adaptive stopping and the environment's recipe (sample polish and
  final refinement, what the agents run), capped at ``max_iterations``
  (``"<method> (adaptive)"``); and with their own stopping and the core's
  defaults, the paper's recipe (``"<method> (adaptive, textbook)"``). The two
  adaptive runs are made at the fixed-budget settings.
- The oracle reads the ground-truth labels: an upper bound, labelled as such.

Per-frame rows carry :func:`stereovo.metrics.frame_metrics` fields and are
aggregated with :func:`stereovo.benchmark.aggregate`. Everything except the
wall-time column ``time_s`` (and the time statistics) is a function of the
seed: worker count and completion order change nothing.

Layout: :mod:`agents.evaluation.setup` holds the agents, the settings and the rows' format;
this module runs the protocol; :mod:`agents.evaluation.report` summarizes the rows and writes the
tables, figures and files. Import each name from the module that defines it.
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass
from functools import partial
from typing import Any, Mapping, Sequence

import numpy as np

from agents.evaluation.report import summarize_evaluation
from agents.evaluation.setup import (
    KIND_ADAPTIVE,
    KIND_AGENT,
    KIND_AGENT_ADAPTIVE,
    KIND_FIXED,
    KIND_TEXTBOOK,
    ROW_COLUMNS,
    AgentSpec,
    IN_FRAME_KIND,
    EvalConfig,
    EvaluationResult,
)
from agents.policies import Policy
from agents.rollout import make_env
from stereovo.options import Integer
from vo_gym.settings import FieldError

__all__ = [
    "check_environments",
    "episode_frames",
    "run_agent_episode",
    "run_classical_episode",
    "run_evaluation",
    "evaluation_units",
    "warm_up_worker",
]


def check_environments(config: EvalConfig) -> None:
    """Build (and close) the environment of every setting of ``config`` once, running nothing.

    Raises:
        FieldError: (a ValueError) an unknown id (with the closest registered one) or a keyword argument
            the environment refuses; its ``field`` is the config field that set the refused keyword
            (:func:`_refused_field`), its message starts with ``environment 'ID':``.
    """
    import vo_gym
    from vo_gym.names import did_you_mean

    if config.env_id not in vo_gym.ENV_IDS:
        try:
            make_env(config.env_id).close()  # Gymnasium's own message first, when it refuses the id
        except (TypeError, ValueError) as err:
            raise FieldError("env_id", _refusal(config.env_id, err), subject="") from None
        raise FieldError("env_id", f"environment {config.env_id!r} is not a vo_gym id"
                                   f"{did_you_mean(config.env_id, vo_gym.ENV_IDS)}", subject="")
    for epsilon, budget in config.settings():
        try:
            make_env(config.env_id, **config.env_kwargs_for(epsilon, budget)).close()
        except (TypeError, ValueError) as err:
            raise _refused_field(config, epsilon, budget, err) from None


def _refusal(env_id: str, err: BaseException) -> str:
    """An environment's refusal in one message that starts with ``environment 'ID':``."""
    text = str(err).split(" was raised from the environment creator")[0]
    return text if text.startswith("environment ") else f"environment {env_id!r}: {text}"


def _refused_field(config: EvalConfig, epsilon: float, budget: int, err: BaseException) -> FieldError:
    """The refusal of the setting ``(epsilon, budget)``'s environment as a :class:`FieldError` whose
    ``field`` is the config field that set the keyword it refuses.

    The environment's messages name its own keywords, not the config's fields (and one of them may
    name two: a ``noise_sigma`` too large *when frames have outliers*), so the field is found by
    building, not by reading the message: the id alone (``env_id``: its registered keywords), then the
    keywords of ``frames_per_episode``, ``n``, the contamination (``epsilons``, or ``sweep_epsilon`` for
    the budget sweep's), the budget (``budget`` or ``budgets``), ``score_auc`` and last ``env_kwargs``
    added one field at a time; the first that the environment refuses is named, with its message.
    Call it once the setting's environment was refused (``err``; the last build is the whole setting).
    """
    kwargs = config.env_kwargs_for(epsilon, budget)
    field_of = {"n_frames": "frames_per_episode", "n_correspondences": "n",
                "outlier_ratio": "epsilons" if epsilon in config.epsilons else "sweep_epsilon",
                "budget": "budget" if budget == config.budget else "budgets"}
    if config.score_auc is not None:  # else a score_auc keyword is env_kwargs'
        field_of["score_auc"] = "score_auc"
    groups: dict[str, dict[str, Any]] = {"env_id": {}}
    for field in (*field_of.values(), "env_kwargs"):
        groups.setdefault(field, {})
    for key, value in kwargs.items():
        groups[field_of.get(key, "env_kwargs")][key] = value
    built: dict[str, Any] = {}
    for field, keywords in groups.items():
        built.update(keywords)
        try:
            make_env(config.env_id, **built).close()
        except (TypeError, ValueError) as refusal:
            return FieldError(field, _refusal(config.env_id, refusal), subject="")
    # the whole setting built this time (an environment that refuses at random): the id is all there is to name
    return FieldError("env_id", _refusal(config.env_id, err), subject="")


def episode_frames(env, seed: int) -> list:
    """Reset ``env`` with ``seed`` and return the episode's frame pairs (k = 1..n_frames).

    They are what any agent stepping this env from this seed sees: the environment draws
    them from the seed alone.
    """
    base = env.unwrapped
    base.reset(seed=seed)
    sequence = base.sequence
    return [sequence.frame(k) for k in range(1, base.sim_config.n_frames + 1)]


def _setting_columns(epsilon: float, budget: int, env) -> dict[str, Any]:
    base = env.unwrapped
    return {"epsilon": float(epsilon), "budget": int(budget), "n": int(base.n_correspondences),
            "score_auc": float(base.sim_config.score_auc)}


def run_agent_episode(
    agent: AgentSpec | Policy, env_id: str, env_kwargs: Mapping[str, Any], seed: int, episode: int = 0,
    label: str | None = None, kind: str | None = None, budget_column: int | None = None,
) -> list[dict[str, Any]]:
    """One episode of ``agent`` (a spec or any policy with ``act``) from ``seed``: one row per frame.

    ``kind`` overrides the rows' kind; ``budget_column`` their budget (an adaptive run, ``budget=None``
    in ``env_kwargs``, is filed under the fixed-budget setting it sits beside)."""
    env = make_env(env_id, **env_kwargs)
    try:
        policy = agent.build(env) if isinstance(agent, AgentSpec) else agent
        name = label or (agent.label if isinstance(agent, AgentSpec) else getattr(agent, "name", "agent"))
        if kind is None:
            kind = agent.row_kind if isinstance(agent, AgentSpec) else KIND_AGENT
        budget = env_kwargs["budget"] if budget_column is None else budget_column
        common = _setting_columns(env_kwargs["outlier_ratio"], budget, env)
        obs, _ = env.reset(seed=seed)
        rows, done = [], False
        while not done:
            frame = env.unwrapped.current_frame
            n_true = int(np.count_nonzero(frame.truth.inlier))
            start = time.perf_counter()
            action = policy.act(obs)
            obs, reward, terminated, truncated, info = env.step(action)
            elapsed = time.perf_counter() - start
            done = terminated or truncated
            row = {**common, "episode": episode, "seed": seed, "frame": int(info["frame"]), "method": name,
                   "kind": kind, **{k: info[k] for k in _METRIC_KEYS}, "n_true_inliers": n_true,
                   "frame_outlier_ratio": float(info["outlier_ratio"]), "reward": float(reward), "time_s": elapsed}
            rows.append({c: row[c] for c in ROW_COLUMNS})
        return rows
    finally:
        env.close()


_METRIC_KEYS = ("success", "rot_err_deg", "trans_err_m", "t_true_norm_m", "precision", "recall", "n_inliers",
                "n_hypotheses", "n_scored", "n_point_checks", "status")
_CLASSICAL_TAG = 0x636C6173  # "clas"


def classical_estimators_for(config: EvalConfig, budget: int, adaptive: bool) -> list[tuple[str, str, Any]]:
    """``(label, kind, estimator)`` of the classical methods at one budget (and adaptive ones if asked)."""
    from stereovo import benchmark as bm
    from stereovo.estimation import method_spec
    from vo_gym.settings import DEFAULT_ESTIMATOR_OPTIONS

    out = []
    for name in config.methods:
        base = bm.GUIDED_VARIANTS.get(name, (name, None))[0]
        if method_spec(base).build is not None:  # a sampling loop: comparable at a fixed budget
            fixed_options = {**DEFAULT_ESTIMATOR_OPTIONS, "budget": int(budget), "batch_size": int(budget)}
            [(_, est)] = bm.classical_estimators([name], **fixed_options)
            out.append((f"{name} (fixed)", KIND_FIXED, est))
    if adaptive:
        for name in config.methods:
            # The environment's recipe (sample polish, final refinement), as the agents run: a difference
            # to an agent is then the sampler's and the stop's, not the recipe's.
            try:
                [(_, est)] = bm.classical_estimators([name], **DEFAULT_ESTIMATOR_OPTIONS,
                                                     max_iterations=config.max_iterations)
            except ValueError:  # a method that takes no such step keeps only its textbook row
                pass
            else:
                out.append((f"{name} (adaptive)", KIND_ADAPTIVE, est))
        for name in config.methods:
            [(_, est)] = bm.classical_estimators([name], max_iterations=config.max_iterations)
            out.append((f"{name} (adaptive, textbook)", KIND_TEXTBOOK, est))
    return out


def run_classical_episode(
    estimators: Sequence[tuple[str, str, Any]], env_id: str, env_kwargs: Mapping[str, Any], seed: int,
    episode: int = 0, base_seed: int = 0,
) -> list[dict[str, Any]]:
    """Classical estimators on the frames of the episode an agent would see from ``seed``: rows frame-major.

    Each estimator's generator is seeded from ``(base_seed, epsilon, budget, seed, frame, name)``.
    An estimator that raises is recorded as a failure with ``status = "error: ..."``.
    """
    from stereovo.benchmark import measure_estimator, quantize, stable_int

    env = make_env(env_id, **env_kwargs)
    try:
        frames = episode_frames(env, seed)
        common = _setting_columns(env_kwargs["outlier_ratio"], env_kwargs["budget"], env)
    finally:
        env.close()
    eps_key = quantize(common["epsilon"])
    rows = []
    for frame in frames:
        for label, kind, estimator in estimators:
            ss = np.random.SeedSequence(
                base_seed, spawn_key=(_CLASSICAL_TAG, eps_key, common["budget"], seed, frame.index,
                                      stable_int(label))
            )
            metrics, elapsed = measure_estimator(estimator, frame, np.random.default_rng(ss))
            rows.append(_estimate_row(common, episode, seed, frame, label, kind, metrics, elapsed))
    return rows


def _estimate_row(common: Mapping[str, Any], episode: int, seed: int, frame, label: str, kind: str,
                  metrics: Mapping[str, Any], elapsed: float) -> dict[str, Any]:
    """The row of an estimator run outside the environment on one of an episode's frames (no reward)."""
    row = {**common, "episode": episode, "seed": seed, "frame": frame.index, "method": label, "kind": kind,
           **{k: metrics[k] for k in _METRIC_KEYS}, "n_true_inliers": int(np.count_nonzero(frame.truth.inlier)),
           "frame_outlier_ratio": float(frame.truth.outlier_ratio), "reward": math.nan, "time_s": elapsed}
    return {c: row[c] for c in ROW_COLUMNS}


_IN_FRAME_TAG = 0x696E6672  # "infr"


def run_in_frame_episode(
    agent: AgentSpec, env_id: str, env_kwargs: Mapping[str, Any], seed: int, episode: int = 0,
    base_seed: int = 0, adaptive: bool = False, budget_column: int | None = None,
) -> list[dict[str, Any]]:
    """An in-frame sampler on the frames of the episode an agent would see from ``seed``: one row per frame.

    It runs through :class:`agents.LearnedEstimator` at ``env_kwargs["budget"]`` hypotheses (batch
    after batch, its stop unused) or, with ``adaptive``, under its own stop (its training cap, 64).
    One generator per episode, seeded from ``(base_seed, epsilon, budget, seed, label)``; the
    estimator keeps its previous motion from frame to frame and forgets it at the episode's start.
    """
    from agents.estimator import LearnedEstimator
    from stereovo.benchmark import measure_estimator, quantize, stable_int

    env = make_env(env_id, **env_kwargs)
    try:
        frames = episode_frames(env, seed)
        budget = env_kwargs["budget"] if budget_column is None else budget_column
        common = _setting_columns(env_kwargs["outlier_ratio"], budget, env)
    finally:
        env.close()
    estimator = LearnedEstimator(agent.source, budget=None if adaptive else int(env_kwargs["budget"]))
    label = f"{agent.label} (adaptive)" if adaptive else agent.label
    rng = np.random.default_rng(np.random.SeedSequence(
        base_seed, spawn_key=(_IN_FRAME_TAG, quantize(common["epsilon"]), common["budget"], seed, stable_int(label))))

    def call(frame, generator):
        return estimator.estimate(frame.prev, frame.curr, frame.camera, frame.scores, rng=generator)

    kind = KIND_AGENT_ADAPTIVE if adaptive else KIND_AGENT
    return [_estimate_row(common, episode, seed, frame, label, kind, *measure_estimator(call, frame, rng))
            for frame in frames]


@dataclass(frozen=True)
class _Unit:
    """One piece of work: an agent's episode, or the classical methods on one episode's frames."""

    epsilon: float
    budget: int
    episode: int
    seed: int
    agent: AgentSpec | None  # None: the classical methods
    weight: int  # frames x estimators, for the progress bar
    adaptive: bool = False  # an agent with no budget: its priors and the prior-aware stop


def _run_unit(unit: _Unit, config: EvalConfig) -> list[dict[str, Any]]:
    kwargs = config.env_kwargs_for(unit.epsilon, unit.budget)
    if unit.agent is not None and unit.agent.kind == IN_FRAME_KIND:
        return run_in_frame_episode(unit.agent, config.env_id, kwargs, unit.seed, unit.episode, config.seed,
                                    adaptive=unit.adaptive)
    if unit.agent is not None and unit.adaptive:
        kwargs = {**kwargs, "budget": None, "max_iterations": config.max_iterations}
        return run_agent_episode(unit.agent, config.env_id, kwargs, unit.seed, unit.episode,
                                 label=f"{unit.agent.label} (adaptive)", kind=KIND_AGENT_ADAPTIVE,
                                 budget_column=unit.budget)
    if unit.agent is not None:
        return run_agent_episode(unit.agent, config.env_id, kwargs, unit.seed, unit.episode)
    adaptive = unit.budget == config.budget
    estimators = classical_estimators_for(config, unit.budget, adaptive)
    return run_classical_episode(estimators, config.env_id, kwargs, unit.seed, unit.episode, config.seed)


def _worker_init() -> None:
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    try:
        import torch

        torch.set_num_threads(1)
    except ImportError:  # pragma: no cover
        pass


def evaluation_units(config: EvalConfig, agents: Sequence[AgentSpec]) -> list[_Unit]:
    """Every unit of work of an evaluation, in the rows' canonical order (its index is its trial key)."""
    units: list[_Unit] = []
    n_fixed = sum(1 for _ in config.methods)  # upper bound for the bar's weights
    for epsilon, budget in config.settings():
        for episode, seed in enumerate(config.episode_seeds()):
            for agent in agents:
                units.append(_Unit(epsilon, budget, episode, seed, agent, config.frames_per_episode))
            if config.adaptive_agents and budget == config.budget:
                for agent in agents:
                    if agent.kind != "oracle":
                        units.append(_Unit(epsilon, budget, episode, seed, agent, config.frames_per_episode, True))
            if config.methods:
                n_est = n_fixed * (3 if budget == config.budget else 1)
                units.append(_Unit(epsilon, budget, episode, seed, None, config.frames_per_episode * n_est))
    return units


def warm_up_worker(config: EvalConfig, agents: Sequence[AgentSpec]) -> None:
    """One thread per worker, then every classical estimator and agent once on a small frame.

    Run once per worker process before its first unit, so numba compiling (or loading its cache)
    and torch's first call never land in a timed row. Errors are ignored: the real units record them.
    """
    from stereovo.benchmark import warm_up_estimators

    _worker_init()
    warm_up_estimators([(label, est) for label, _, est in classical_estimators_for(config, config.budget, True)])
    kwargs = {**config.env_kwargs_for(config.sweep_epsilon, config.budget), "n_frames": 1}
    for agent in agents:
        try:
            if agent.kind == IN_FRAME_KIND:
                run_in_frame_episode(agent, config.env_id, kwargs, seed=0)
            else:
                run_agent_episode(agent, config.env_id, kwargs, seed=0)
        except Exception:  # noqa: BLE001 - the evaluation itself reports a failing agent
            pass


def run_evaluation(
    config: EvalConfig, agents: Sequence[AgentSpec], workers: int = 1, progress: bool = True,
    backend: Any = None, journal: Any = None, done: Mapping[int, list[dict[str, Any]]] | None = None,
) -> EvaluationResult:
    """Run every agent and classical method on every setting's episodes; rows in a fixed order.

    Args:
        workers: processes of the default local backend (1: this process).
        backend: a :class:`stereovo.trials.Backend` (None: a local one with ``workers``, closed here).
        journal: an opened :class:`stereovo.trials.TrialJournal`; each finished unit (an agent's
            episode, or the classical methods on one episode) is appended to it at once.
        done: rows of units already in the journal, by unit index (see :func:`evaluation_units`).

    Raises:
        stereovo.trials.RunInterrupted: Ctrl-C; every finished unit is in ``journal``.
    """
    from stereovo.trials import Task, make_backend, run_tasks

    workers = Integer(low=1).check("workers", workers, prefix="")
    check_environments(config)
    units = evaluation_units(config, agents)
    owned = backend is None
    backend = make_backend("local", int(workers)) if owned else backend
    start = time.perf_counter()
    try:
        result = run_tasks(
            partial(_run_unit, config=config), [Task(i, u, u.weight) for i, u in enumerate(units)], backend,
            journal=journal, done=dict(done or {}), warmup=partial(warm_up_worker, config, tuple(agents)),
            progress=progress, desc="evaluate", unit="frame",
        )
    finally:
        if owned:
            backend.close()
    wall = time.perf_counter() - start
    rows = [row for i in range(len(units)) for row in result.results[i]]
    order = [a.label for a in agents]
    return EvaluationResult(config, list(agents), rows, summarize_evaluation(rows, config, order), wall)
