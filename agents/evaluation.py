"""Evaluation of sampling agents side by side with classical methods, on the same held-out frames.

What ``vo-gym evaluate`` runs, reusable from Python (:func:`success_rate` is
:func:`agents.rollout.success_rate`, what the PPO trainer's callback measures).

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
  get their features from their own previous estimates, as in training).
  Classical methods run twice: with the environment's estimator settings at the
  same fixed budget (``"<method> (fixed)"``, the like-for-like comparison) and
  with their own adaptive stopping and the core's defaults, capped at
  ``max_iterations`` (``"<method> (adaptive)"``, at the fixed-budget settings).
- The oracle reads the ground-truth labels: an upper bound, labelled as such.

Per-frame rows carry :func:`stereovo.metrics.frame_metrics` fields and are
aggregated with :func:`stereovo.benchmark.aggregate`. Everything except the
wall-time column ``time_s`` (and the time statistics) is a function of the
seed: worker count and completion order change nothing.
"""

from __future__ import annotations

import math
import os
import time
import zlib
from dataclasses import asdict, dataclass, field
from functools import partial
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, Sequence

import numpy as np

from agents.policies import HEURISTICS, OraclePolicy, Policy, make_heuristic
from agents.rollout import make_env, success_rate
from stereovo.reporting import (
    ERROR_FLOOR,
    check_plot_format,
    figure,
    format_number,
    format_percent,
    line_style,
    plot_success,
    save_figure,
)

__all__ = [
    "ORACLE",
    "ORACLE_LABEL",
    "DEFAULT_METHODS",
    "METHOD_ALIASES",
    "AgentSpec",
    "resolve_agent",
    "resolve_agents",
    "EvalConfig",
    "episode_frames",
    "run_agent_episode",
    "run_classical_episode",
    "success_rate",
    "EvaluationResult",
    "run_evaluation",
    "evaluation_units",
    "warm_up_worker",
    "parse_row_value",
    "summarize_evaluation",
    "evaluation_markdown",
    "write_evaluation",
]

ORACLE = "oracle"
ORACLE_LABEL = "oracle (upper bound)"
DEFAULT_METHODS: tuple[str, ...] = ("ransac", "msac", "prosac", "ransac+guided")
METHOD_ALIASES: dict[str, str] = {"guided": "ransac+guided", "guided-ransac": "ransac+guided"}
CHECKPOINT_SUFFIXES = (".pt", ".zip")

KIND_AGENT = "agent"
KIND_ORACLE = "upper bound"
KIND_FIXED = "classical, fixed budget"
KIND_ADAPTIVE = "classical, adaptive"
KIND_AGENT_ADAPTIVE = "agent, adaptive"  # the agent's priors with the prior-aware adaptive stop

ROW_COLUMNS: tuple[str, ...] = (
    "epsilon", "budget", "n", "score_auc", "episode", "seed", "frame", "method", "kind", "success",
    "rot_err_deg", "trans_err_m", "t_true_norm_m", "precision", "recall", "n_inliers", "n_true_inliers",
    "n_hypotheses", "n_scored", "n_point_checks", "status", "frame_outlier_ratio", "reward", "time_s",
)
"""Columns of a per-frame row; ``time_s`` (agent action + environment step, or the estimator call) is the
only one that differs between two runs with one seed."""

STAT_KEYS: tuple[str, ...] = (
    "frames", "success_rate", "median_rot_err_deg", "median_trans_err_m", "mean_precision", "mean_recall",
    "mean_hypotheses", "median_hypotheses", "n_failed", "n_errors", "median_time_ms",
)
TIME_KEYS: tuple[str, ...] = ("median_time_ms",)


# --------------------------------------------------------------------------- agents


@dataclass(frozen=True)
class AgentSpec:
    """An agent to evaluate, rebuilt on demand (picklable, for worker processes).

    Attributes:
        label: the name in tables and rows.
        kind: ``"heuristic"``, ``"oracle"`` or ``"checkpoint"``.
        source: the heuristic's name, or the checkpoint path (``.pt`` from
            :func:`agents.checkpoint.save_checkpoint`, or a PPO ``.zip``).
    """

    label: str
    kind: str
    source: str

    @property
    def row_kind(self) -> str:
        return KIND_ORACLE if self.kind == "oracle" else KIND_AGENT

    def build(self, env) -> Policy:
        """The policy for ``env`` (the oracle reads the labels of ``env.unwrapped.current_frame``)."""
        if self.kind == "heuristic":
            return make_heuristic(self.source)
        if self.kind == "oracle":
            base = env.unwrapped
            return OraclePolicy(lambda: base.current_frame.truth.inlier)
        if self.kind == "checkpoint":
            return load_agent_checkpoint(self.source, self.label)
        raise ValueError(f"unknown agent kind {self.kind!r}")


def load_agent_checkpoint(path: str | os.PathLike, name: str | None = None):
    """A :class:`agents.checkpoint.LearnedPolicy` from a ``.pt`` checkpoint or a PPO ``.zip`` (its actor).

    Raises:
        FileNotFoundError: no such file.
        ValueError: not a vo-gym checkpoint, or trained on another feature layout.
    """
    from agents.checkpoint import LearnedPolicy

    path = Path(path)
    if path.suffix == ".zip":
        from agents.ppo import load_ppo_actor

        return LearnedPolicy(load_ppo_actor(path), name or path.stem)
    return LearnedPolicy.from_checkpoint(path, name)


def resolve_agent(text: str) -> AgentSpec:
    """``uniform``/``match-score``/``consistency``/``constant-velocity``, ``oracle``, a shipped sampler's
    name (:data:`agents.checkpoint.SHIPPED_SAMPLERS`) or a checkpoint path.

    A checkpoint is loaded once here, so a missing file, a foreign file or another feature
    layout is reported before anything runs.

    Raises:
        ValueError: an unknown name, or a checkpoint that cannot be used (the message says why).
        FileNotFoundError: a checkpoint path that does not exist.
    """
    from agents.checkpoint import SHIPPED_SAMPLERS, shipped_checkpoint

    name = text.strip()
    if name in HEURISTICS:
        return AgentSpec(name, "heuristic", name)
    if name == ORACLE:
        return AgentSpec(ORACLE_LABEL, "oracle", ORACLE)
    if name in SHIPPED_SAMPLERS:  # a packaged sampler by name, found wherever the package is installed
        with shipped_checkpoint(name) as shipped:
            load_agent_checkpoint(shipped)
            return AgentSpec(name, "checkpoint", str(shipped))
    path = Path(name).expanduser()
    looks_like_path = path.suffix in CHECKPOINT_SUFFIXES or os.sep in name or path.exists()
    if not looks_like_path:
        raise ValueError(
            f"unknown agent {name!r}: not a heuristic ({', '.join(HEURISTICS)}), not {ORACLE!r}, not a shipped "
            f"sampler ({', '.join(SHIPPED_SAMPLERS)}) and not a checkpoint file (.pt or PPO .zip)"
        )
    if not path.is_file():
        raise FileNotFoundError(f"agent {name!r}: no checkpoint at {path}")
    load_agent_checkpoint(path)  # raises with a clear message on a foreign file or feature layout
    return AgentSpec(path.stem, "checkpoint", str(path))


def resolve_agents(texts: Sequence[str]) -> list[AgentSpec]:
    """Resolve every agent; checkpoints whose file names clash get their parent folder in the label."""
    specs = [resolve_agent(t) for t in texts]
    if not specs:
        raise ValueError("no agents to evaluate")
    seen: dict[str, int] = {}
    for s in specs:
        seen[s.label] = seen.get(s.label, 0) + 1
    out = []
    for s in specs:
        if s.kind == "checkpoint" and seen[s.label] > 1:
            s = AgentSpec(f"{Path(s.source).parent.name}/{s.label}", s.kind, s.source)
        out.append(s)
    labels = [s.label for s in out]
    dupes = sorted({x for x in labels if labels.count(x) > 1})
    if dupes:
        raise ValueError(f"agent(s) given twice: {', '.join(dupes)}")
    return out


# --------------------------------------------------------------------------- settings


@dataclass(frozen=True)
class EvalConfig:
    """What to evaluate on. See the module doc for the protocol.

    Attributes:
        env_id: a registered vo_gym id; its registered keyword arguments apply.
        episodes: episodes (trajectories) per setting; episode ``i`` uses seed ``seed + i``.
        frames_per_episode: frame pairs per episode (the env's ``n_frames``).
        seed: first episode seed (keep it away from training seeds).
        budget: hypotheses per frame of the contamination sweep.
        epsilons: contaminations of the sweep (a).
        budgets: hypothesis budgets of the sweep (b).
        sweep_epsilon: contamination of the budget sweep.
        n: correspondences per frame.
        score_auc: match-score AUC; None keeps the env id's (0.75 for ``StereoVO-v0``).
        methods: classical methods (names of :func:`stereovo.benchmark.benchmark_methods` or aliases).
        max_iterations: hypothesis cap of the adaptive classical runs.
        env_kwargs: further keyword arguments of the environment (e.g. ``noise_sigma``).
        success_target: the success rate of "hypotheses needed" (0.99).
        adaptive_agents: also run every agent at the fixed-budget settings with no budget: its
            priors and the estimator's prior-aware adaptive stop (q of the agent's weighted draw,
            capped at ``max_iterations``), rows ``"<agent> (adaptive)"`` beside the classical
            adaptive ones (PROSAC's own stop among them).
    """

    env_id: str = "vo_gym/StereoVO-v0"
    episodes: int = 10
    frames_per_episode: int = 10
    seed: int = 1000
    budget: int = 16
    epsilons: tuple[float, ...] = (0.3, 0.5, 0.7, 0.8, 0.9)
    budgets: tuple[int, ...] = (1, 2, 4, 8, 16, 32, 64)
    sweep_epsilon: float = 0.8
    n: int = 500
    score_auc: float | None = None
    methods: tuple[str, ...] = DEFAULT_METHODS
    max_iterations: int = 2000
    env_kwargs: Mapping[str, Any] = field(default_factory=dict)
    success_target: float = 0.99
    adaptive_agents: bool = False

    def __post_init__(self) -> None:
        def positive(name: str, value: Any) -> int:
            if isinstance(value, bool) or int(value) != value or value < 1:
                raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
            return int(value)

        if not isinstance(self.adaptive_agents, bool):
            raise ValueError(f"adaptive_agents must be True or False, got {self.adaptive_agents!r}")
        for name in ("episodes", "frames_per_episode", "budget", "n", "max_iterations"):
            object.__setattr__(self, name, positive(name, getattr(self, name)))
        if isinstance(self.seed, bool) or int(self.seed) != self.seed or self.seed < 0:
            raise ValueError(f"seed must be an integer >= 0, got {self.seed!r}")
        eps = tuple(float(e) for e in self.epsilons)
        if not eps or not all(0.0 <= e < 1.0 for e in eps) or len(set(eps)) != len(eps):
            raise ValueError(f"epsilons must be distinct values in [0, 1), got {self.epsilons}")
        object.__setattr__(self, "epsilons", eps)
        budgets = tuple(positive("every budget", b) for b in self.budgets)
        if not budgets or len(set(budgets)) != len(budgets):
            raise ValueError(f"budgets must be distinct integers >= 1, got {self.budgets}")
        object.__setattr__(self, "budgets", tuple(sorted(budgets)))
        if not 0.0 <= float(self.sweep_epsilon) < 1.0:
            raise ValueError(f"sweep_epsilon must be in [0, 1), got {self.sweep_epsilon}")
        object.__setattr__(self, "sweep_epsilon", float(self.sweep_epsilon))
        object.__setattr__(self, "methods", tuple(normalize_methods(self.methods)))
        reserved = {"n_frames", "n_correspondences", "outlier_ratio", "budget"} & set(self.env_kwargs)
        if reserved:
            raise ValueError(f"env_kwargs must not set {sorted(reserved)}: the evaluation's own options do")
        object.__setattr__(self, "env_kwargs", dict(self.env_kwargs))

    def env_kwargs_for(self, epsilon: float, budget: int) -> dict[str, Any]:
        kwargs = {
            **self.env_kwargs, "n_frames": self.frames_per_episode, "n_correspondences": self.n,
            "outlier_ratio": float(epsilon), "budget": int(budget),
        }
        if self.score_auc is not None:
            kwargs["score_auc"] = float(self.score_auc)
        return kwargs

    def settings(self) -> list[tuple[float, int]]:
        """Every ``(epsilon, budget)`` to run, each once: sweep (a), then (b)."""
        out = [(e, self.budget) for e in self.epsilons] + [(self.sweep_epsilon, self.budget)]
        out += [(self.sweep_epsilon, b) for b in self.budgets]
        return list(dict.fromkeys(out))

    def episode_seeds(self) -> list[int]:
        return [self.seed + i for i in range(self.episodes)]

    def as_dict(self) -> dict[str, Any]:
        d = asdict(self)
        for key in ("epsilons", "budgets", "methods"):
            d[key] = list(d[key])
        return d


def normalize_methods(names: Iterable[str]) -> list[str]:
    """Aliases resolved, duplicates dropped, unknown names refused (listing the known ones)."""
    from stereovo import benchmark as bm

    known = bm.benchmark_methods()
    out = list(dict.fromkeys(METHOD_ALIASES.get(n.strip(), n.strip()) for n in names if n.strip()))
    unknown = [n for n in out if n not in known]
    if unknown:
        raise ValueError(
            f"unknown classical method(s): {', '.join(unknown)}; available: {', '.join(known)}"
            f" (aliases: {', '.join(f'{a}={b}' for a, b in METHOD_ALIASES.items())})"
        )
    return out


# --------------------------------------------------------------------------- running


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
    from vo_gym.env import DEFAULT_ESTIMATOR_OPTIONS

    out = []
    for name in config.methods:
        base = bm.GUIDED_VARIANTS.get(name, (name, None))[0]
        if method_spec(base).build is not None:  # a sampling loop: comparable at a fixed budget
            fixed_options = {**DEFAULT_ESTIMATOR_OPTIONS, "budget": int(budget), "batch_size": int(budget)}
            [(_, est)] = bm.classical_estimators([name], **fixed_options)
            out.append((f"{name} (fixed)", KIND_FIXED, est))
    if adaptive:
        for name in config.methods:
            [(_, est)] = bm.classical_estimators([name], max_iterations=config.max_iterations)
            out.append((f"{name} (adaptive)", KIND_ADAPTIVE, est))
    return out


def run_classical_episode(
    estimators: Sequence[tuple[str, str, Any]], env_id: str, env_kwargs: Mapping[str, Any], seed: int,
    episode: int = 0, base_seed: int = 0,
) -> list[dict[str, Any]]:
    """Classical estimators on the frames of the episode an agent would see from ``seed``: rows frame-major.

    Each estimator's generator is seeded from ``(base_seed, epsilon, budget, seed, frame, name)``.
    An estimator that raises is recorded as a failure with ``status = "error: ..."``.
    """
    from stereovo.benchmark import measure_estimator

    env = make_env(env_id, **env_kwargs)
    try:
        frames = episode_frames(env, seed)
        common = _setting_columns(env_kwargs["outlier_ratio"], env_kwargs["budget"], env)
    finally:
        env.close()
    eps_key = int(round(common["epsilon"] * 1_000_000))
    rows = []
    for frame in frames:
        n_true = int(np.count_nonzero(frame.truth.inlier))
        for label, kind, estimator in estimators:
            ss = np.random.SeedSequence(
                base_seed, spawn_key=(_CLASSICAL_TAG, eps_key, common["budget"], seed, frame.index,
                                      zlib.crc32(label.encode()))
            )
            metrics, elapsed = measure_estimator(estimator, frame, np.random.default_rng(ss))
            row = {**common, "episode": episode, "seed": seed, "frame": frame.index, "method": label, "kind": kind,
                   **{k: metrics[k] for k in _METRIC_KEYS}, "n_true_inliers": n_true,
                   "frame_outlier_ratio": float(frame.truth.outlier_ratio), "reward": math.nan, "time_s": elapsed}
            rows.append({c: row[c] for c in ROW_COLUMNS})
    return rows


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


@dataclass
class EvaluationResult:
    config: EvalConfig
    agents: list[AgentSpec]
    rows: list[dict[str, Any]]
    summary: dict[str, Any]
    wall_s: float


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
                n_est = n_fixed * (2 if budget == config.budget else 1)
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
            run_agent_episode(agent, config.env_id, kwargs, seed=0)
        except Exception:  # noqa: BLE001 - the evaluation itself reports a failing agent
            pass


_ROW_INTS = {"budget", "n", "episode", "seed", "frame", "n_inliers", "n_true_inliers", "n_hypotheses", "n_scored",
             "n_point_checks"}
_ROW_STRS = {"method", "kind", "status"}


def parse_row_value(column: str, text: str) -> Any:
    """A ``frames.csv`` cell's value with its type restored (see :data:`ROW_COLUMNS`)."""
    if column in _ROW_STRS:
        return text
    if column == "success":
        if text not in ("True", "False"):
            raise ValueError(f"column success: expected True/False, got {text!r}")
        return text == "True"
    if column in _ROW_INTS:
        return int(text)
    return float(text)


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

    if isinstance(workers, bool) or int(workers) != workers or workers < 1:
        raise ValueError(f"workers must be an integer >= 1, got {workers!r}")
    make_env(config.env_id, **config.env_kwargs_for(config.sweep_epsilon, config.budget)).close()  # validates
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


# --------------------------------------------------------------------------- summary


def _stats(rows: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    from stereovo.benchmark import aggregate

    agg = aggregate(rows)
    return {k: _json_number(agg[k]) for k in STAT_KEYS}


def _json_number(value: Any) -> Any:
    if isinstance(value, (float, np.floating)):
        value = float(value)
        return value if math.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    return value


def summarize_evaluation(
    rows: Sequence[Mapping[str, Any]], config: EvalConfig, agent_order: Sequence[str] = ()
) -> dict[str, Any]:
    """A JSON-ready summary: both sweeps per method, the adaptive runs, hypotheses for 99 % success.

    Keys of the per-value dicts are strings (``"0.8"``, ``"16"``) so the summary survives JSON.
    """
    kinds = {r["method"]: r["kind"] for r in rows}
    rank = {KIND_AGENT: 0, KIND_ORACLE: 1, KIND_FIXED: 2, KIND_ADAPTIVE: 3, KIND_AGENT_ADAPTIVE: 4}
    first_seen = list(dict.fromkeys(r["method"] for r in rows))
    agent_pos = {name: i for i, name in enumerate(agent_order)}
    methods = sorted(first_seen, key=lambda m: (rank[kinds[m]], agent_pos.get(m, 0), first_seen.index(m)))

    groups: dict[tuple, list[Mapping[str, Any]]] = {}
    for r in rows:
        groups.setdefault((r["method"], float(r["epsilon"]), int(r["budget"])), []).append(r)

    def stats(method: str, epsilon: float, budget: int) -> dict[str, Any] | None:
        group = groups.get((method, epsilon, budget))
        return _stats(group) if group else None

    eps_sweep = {
        m: {f"{e:g}": s for e in config.epsilons if (s := stats(m, e, config.budget)) is not None} for m in methods
    }
    budget_methods = [m for m in methods if kinds[m] not in (KIND_ADAPTIVE, KIND_AGENT_ADAPTIVE)]
    budget_sweep = {
        m: {str(b): s for b in config.budgets if (s := stats(m, config.sweep_epsilon, b)) is not None}
        for m in budget_methods
    }
    adaptive = {
        m: s for m in methods if kinds[m] in (KIND_ADAPTIVE, KIND_AGENT_ADAPTIVE)
        if (s := stats(m, config.sweep_epsilon, config.budget)) is not None
    }
    needed: dict[str, int | None] = {}
    for m in budget_methods:
        reached = [b for b in config.budgets
                   if budget_sweep[m].get(str(b), {}).get("success_rate", -1.0) >= config.success_target]
        needed[m] = min(reached) if reached else None
    return {
        "config": config.as_dict(),
        "success_definition": _success_definition(),
        "methods": [{"name": m, "kind": kinds[m]} for m in methods],
        "epsilon_sweep": {"budget": config.budget, "epsilons": list(config.epsilons), "methods": eps_sweep},
        "budget_sweep": {"epsilon": config.sweep_epsilon, "budgets": list(config.budgets), "methods": budget_sweep,
                         "adaptive": adaptive},
        "hypotheses_for_success": {"target": config.success_target, "epsilon": config.sweep_epsilon,
                                   "max_budget": max(config.budgets), "methods": needed},
    }


def _success_definition() -> str:
    from stereovo.benchmark import success_definition

    return success_definition()


def hypotheses_label(summary: Mapping[str, Any], method: str) -> str:
    h = summary["hypotheses_for_success"]
    value = h["methods"].get(method)
    return f"> {h['max_budget']}" if value is None else str(value)


def evaluation_markdown(summary: Mapping[str, Any], wall_s: float | None = None) -> str:
    """The comparison tables (markdown)."""
    from stereovo.benchmark import markdown_table

    cfg = summary["config"]
    kinds = {m["name"]: m["kind"] for m in summary["methods"]}
    eps = summary["epsilon_sweep"]
    bud = summary["budget_sweep"]
    hyp = summary["hypotheses_for_success"]
    frames = cfg["episodes"] * cfg["frames_per_episode"]
    lines = [
        "# Agents vs classical methods on the same frames",
        "",
        f"Environment `{cfg['env_id']}`, N = {cfg['n']}, {cfg['episodes']} episodes x {cfg['frames_per_episode']}"
        f" frames = {frames} frames per setting, episode seeds {cfg['seed']}..{cfg['seed'] + cfg['episodes'] - 1}"
        f" (identical frames for every agent and method of a setting). Success = {summary['success_definition']}.",
        f"Agents and `(fixed)` methods draw exactly the budget's hypotheses with the environment's estimator"
        f" settings; `(adaptive)` methods stop adaptively with the core's defaults, capped at"
        f" {cfg['max_iterations']} hypotheses. The oracle reads the ground-truth labels: an upper bound only.",
    ]
    if wall_s is not None:
        lines.append(f"Wall time {wall_s:.0f} s.")
    lines.append("")

    def table(title: str, per: Mapping[str, Mapping[str, Any]], keys: Sequence[str], header: str, stat: str,
              fmt: Callable[[Any], str], extra: tuple[str, Callable[[str], str]] | None = None) -> None:
        headers = ["method", "kind", *(f"{header} = {k}" for k in keys)]
        if extra:
            headers.append(extra[0])
        body = []
        for m, values in per.items():
            row = [f"`{m}`", kinds[m], *(fmt(values.get(k, {}).get(stat)) for k in keys)]
            if extra:
                row.append(extra[1](m))
            body.append(row)
        lines.extend([f"## {title}", "", markdown_table(headers, body, "ll" + "r" * (len(headers) - 2)), ""])

    eps_keys = [f"{e:g}" for e in eps["epsilons"]]
    table(f"(a) Success rate vs contamination, budget {eps['budget']}", eps["methods"], eps_keys, "eps",
          "success_rate", format_percent)
    table(f"(a) Median rotation error [deg] vs contamination, budget {eps['budget']}", eps["methods"], eps_keys,
          "eps", "median_rot_err_deg", format_number)
    table(f"(a) Median translation error [m] vs contamination, budget {eps['budget']}", eps["methods"], eps_keys,
          "eps", "median_trans_err_m", format_number)
    bud_keys = [str(b) for b in bud["budgets"]]
    table(f"(b) Success rate vs hypothesis budget, eps {bud['epsilon']:g}", bud["methods"], bud_keys, "budget",
          "success_rate", format_percent,
          (f"hyp. for {100 * hyp['target']:g} %", lambda m: hypotheses_label(summary, m)))
    if bud["adaptive"]:
        body = [[f"`{m}`", format_percent(s["success_rate"]), format_number(s["mean_hypotheses"], ".0f"),
                 format_number(s["median_hypotheses"], ".0f"), format_number(s["median_time_ms"], ".1f")]
                for m, s in bud["adaptive"].items()]
        lines += [f"## (b) Adaptive runs at eps {bud['epsilon']:g} (classical methods: their own stopping rule;"
                  f" `<agent> (adaptive)`: the agent's priors with the prior-aware stop)", "",
                  markdown_table(["method", "success", "hypotheses mean", "hypotheses med", "time med [ms]"], body),
                  ""]
    body = [[f"`{m}`", kinds[m], hypotheses_label(summary, m)] for m in hyp["methods"]]
    lines += [f"## Hypotheses needed for {100 * hyp['target']:g} % success at eps {hyp['epsilon']:g}"
              f" (smallest budget of the sweep)", "", markdown_table(["method", "kind", "hypotheses"], body, "llr"), ""]
    return "\n".join(lines).rstrip() + "\n"


# --------------------------------------------------------------------------- outputs

PLOT_NAMES = ("success_vs_epsilon", "success_vs_budget")
PLOT_FILES = tuple(f"{name}.png" for name in PLOT_NAMES)
"""The figures' file names in the default format (PNG); ``write_plots(..., fmt=)`` writes pdf or svg."""


def _line_style(i: int, kind: str) -> dict[str, Any]:
    style = line_style(i)
    style["linestyle"] = {KIND_AGENT: "-", KIND_ORACLE: ":", KIND_FIXED: "--", KIND_ADAPTIVE: "-.",
                          KIND_AGENT_ADAPTIVE: "-."}[kind]
    return style


def write_plots(summary: Mapping[str, Any], out: str | os.PathLike, fmt: str = "png") -> list[Path]:
    """(a) success and median pose errors vs contamination; (b) success vs hypothesis budget.

    Success rates carry their 95 % Wilson band over the frames behind each point; ``fmt`` is the
    file format (png, pdf or svg).
    """
    fmt = check_plot_format(fmt)
    names = [f"{name}.{fmt}" for name in PLOT_NAMES]
    out = Path(out)
    kinds = {m["name"]: m["kind"] for m in summary["methods"]}
    index = {m: i for i, m in enumerate(kinds)}
    eps = summary["epsilon_sweep"]
    fig = figure((16, 5))
    axes = [fig.add_subplot(1, 3, i + 1) for i in range(3)]
    panels = (("success_rate", 100.0, "success rate [%]", False), ("median_rot_err_deg", 1.0,
              "median rotation error [deg]", True), ("median_trans_err_m", 1.0, "median translation error [m]", True))
    for ax, (key, scale, ylabel, logy) in zip(axes, panels):
        for m, per in eps["methods"].items():
            pts = [(float(e), s[key], s.get("frames") or 0) for e, s in per.items() if s.get(key) is not None]
            if not pts:
                continue
            xs, ys, ns = zip(*sorted(pts))
            if key == "success_rate":
                plot_success(ax, xs, ys, ns, m, _line_style(index[m], kinds[m]), scale=scale)
            else:
                ys = [max(y * scale, ERROR_FLOOR) for y in ys] if logy else [y * scale for y in ys]
                ax.plot(xs, ys, label=m, lw=1.3, ms=4, **_line_style(index[m], kinds[m]))
        ax.set_xlabel("contamination epsilon")
        ax.set_ylabel(ylabel)
        ax.set_xticks(list(eps["epsilons"]))
        if logy:
            ax.set_yscale("log")
        else:
            ax.set_ylim(-2, 102)
        ax.grid(True, which="both", alpha=0.3)
    axes[-1].legend(loc="center left", bbox_to_anchor=(1.01, 0.5), fontsize="small")
    fig.suptitle(f"(a) vs contamination at a budget of {eps['budget']} hypotheses (adaptive: own stopping rule)",
                 fontsize="medium")
    paths = [save_figure(fig, out / names[0])]

    bud = summary["budget_sweep"]
    fig = figure((9.5, 5.5))
    ax = fig.add_subplot()
    for m, per in bud["methods"].items():
        pts = [(int(b), s["success_rate"], s.get("frames") or 0) for b, s in per.items()
               if s.get("success_rate") is not None]
        if pts:
            xs, ys, ns = zip(*sorted(pts))
            plot_success(ax, xs, ys, ns, m, _line_style(index[m], kinds[m]))
    for m, s in bud["adaptive"].items():
        if s.get("mean_hypotheses") and s.get("success_rate") is not None:
            style = _line_style(index[m], kinds[m])
            ax.scatter([s["mean_hypotheses"]], [100 * s["success_rate"]], marker=style["marker"], s=60,
                       color=style["color"], label=f"{m} (mean hypotheses)", zorder=3)
    target = summary["hypotheses_for_success"]["target"]
    ax.axhline(100 * target, color="tab:red", ls="--", lw=0.8, label=f"{100 * target:g} % success")
    ax.set_xscale("log", base=2)
    ticks = list(bud["budgets"])
    far = max((s.get("mean_hypotheses") or 0 for s in bud["adaptive"].values()), default=0)
    while ticks and ticks[-1] * 2 <= 2 * far:  # extend the axis' labels to the adaptive runs' hypotheses
        ticks.append(ticks[-1] * 2)
    ax.set_xticks(ticks)
    ax.set_xticklabels([str(b) for b in ticks])
    ax.minorticks_off()
    ax.set_ylim(-2, 102)
    ax.set_xlabel("hypotheses per frame")
    ax.set_ylabel("success rate [%]")
    ax.set_title(f"(b) Success vs hypothesis budget at eps {bud['epsilon']:g}", fontsize="medium")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(loc="center left", bbox_to_anchor=(1.01, 0.5), fontsize="small")
    paths.append(save_figure(fig, out / names[1]))
    return paths


def write_evaluation(result: EvaluationResult, out: str | os.PathLike, plots: bool = True,
                     plot_format: str = "png") -> list[Path]:
    """``frames.csv`` (per-frame rows), ``summary.json``, ``summary.md`` and the plots (``plot_format``:
    png, pdf or svg) under ``out``."""
    if plots:
        check_plot_format(plot_format)  # before anything is written
    import json

    from stereovo.io import write_frame_csv

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    from stereovo.trials.store import atomic_path, atomic_write_text

    with atomic_path(out / "frames.csv") as tmp:  # a reader never sees half a file
        write_frame_csv(tmp, result.rows)
    payload = {**result.summary, "agents": [asdict(a) for a in result.agents], "wall_s": round(result.wall_s, 1)}
    atomic_write_text(out / "summary.json", json.dumps(payload, indent=2) + "\n")
    atomic_write_text(out / "summary.md", evaluation_markdown(result.summary, result.wall_s))
    paths = [out / "frames.csv", out / "summary.json", out / "summary.md"]
    if plots:
        paths += write_plots(result.summary, out, plot_format)
    return paths
