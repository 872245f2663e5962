"""What an evaluation of sampling agents compares, on which settings, and the format of its rows.

:class:`AgentSpec` names an agent (a heuristic, the oracle, a one-shot checkpoint or an in-frame
sampler) and rebuilds it in any worker process; :func:`resolve_agent` turns a command-line name into one, loading a checkpoint once
so that a bad file is refused before anything runs. :class:`EvalConfig` holds the settings of both
sweeps and the classical methods (:func:`normalize_methods`). :data:`ROW_COLUMNS` are the columns
of a per-frame row, ``KIND_*`` the kinds a row can have, :func:`parse_row_value` reads a stored
``frames.csv`` cell back. The protocol itself is in :mod:`agents.evaluation.run`.
"""

from __future__ import annotations

import os
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

from agents.catalog import IN_FRAME_SAMPLERS, SHIPPED_SAMPLERS, shipped_file
from agents.policies import HEURISTICS, OraclePolicy, Policy, make_heuristic
from stereovo.benchmark import typed_value
from stereovo.options import Integer
from stereovo.simulation.scores import SCORE_AUC
from vo_gym.settings import FieldError, check_field, check_fields

ORACLE = "oracle"
ORACLE_LABEL = "oracle (upper bound)"
DEFAULT_METHODS: tuple[str, ...] = ("ransac", "msac", "prosac", "ransac+guided")
METHOD_ALIASES: dict[str, str] = {"guided": "ransac+guided", "guided-ransac": "ransac+guided"}
CHECKPOINT_SUFFIXES = (".pt", ".zip")
IN_FRAME_KIND = "in-frame"

KIND_AGENT = "agent"
KIND_ORACLE = "upper bound"
KIND_FIXED = "classical, fixed budget"
KIND_ADAPTIVE = "classical, adaptive"  # its own stop, the environment's recipe (as the agents)
KIND_TEXTBOOK = "classical, adaptive, textbook"  # its own stop, the core's defaults (the paper's recipe)
KIND_AGENT_ADAPTIVE = "agent, adaptive"  # the agent's priors with the prior-aware adaptive stop

ROW_COLUMNS: tuple[str, ...] = (
    "epsilon", "budget", "n", "score_auc", "episode", "seed", "frame", "method", "kind", "success",
    "rot_err_deg", "trans_err_m", "t_true_norm_m", "precision", "recall", "n_inliers", "n_true_inliers",
    "n_hypotheses", "n_scored", "n_point_checks", "status", "frame_outlier_ratio", "reward", "time_s",
)
"""Columns of a per-frame row; ``time_s`` (agent action + environment step, or the estimator call) is the
only one that differs between two runs with one seed."""


# --------------------------------------------------------------------------- agents


@dataclass(frozen=True)
class AgentSpec:
    """An agent to evaluate, rebuilt on demand (picklable, for worker processes).

    Attributes:
        label: the name in tables and rows.
        kind: ``"heuristic"``, ``"oracle"``, ``"checkpoint"`` (a one-shot sampler, which sets a
            frame's priors through the environment) or ``"in-frame"`` (a sampler that steers the
            search batch by batch; it runs through :class:`agents.LearnedEstimator` on the episode's
            frames, see :func:`agents.evaluation.run.run_in_frame_episode`).
        source: the heuristic's name, the checkpoint path (``.pt`` from
            :func:`agents.checkpoint.save_checkpoint`, or a PPO ``.zip``), or the in-frame sampler's
            shipped name or path.
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
        if self.kind == IN_FRAME_KIND:
            raise ValueError(f"agent {self.label!r} is an in-frame sampler: it runs through "
                             "agents.LearnedEstimator (agents.evaluation.run.run_in_frame_episode), not as an env policy")
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
        from agents.ppo.archive import load_ppo_actor

        return LearnedPolicy(load_ppo_actor(path), name or path.stem)
    return LearnedPolicy.from_checkpoint(path, name)


def resolve_agent(text: str) -> AgentSpec:
    """``uniform``/``match-score``/``consistency``/``constant-velocity``, ``oracle``, a shipped sampler's
    name (one-shot, :data:`agents.catalog.SHIPPED_SAMPLERS`, or in-frame,
    :data:`agents.catalog.IN_FRAME_SAMPLERS`) or a checkpoint path of either kind.

    A checkpoint is loaded once here, so a missing file, a foreign file or another feature
    layout is reported before anything runs.

    Raises:
        ValueError: an unknown name, or a checkpoint that cannot be used (the message says why).
        FileNotFoundError: a checkpoint path that does not exist.
    """
    name = text.strip()
    if name in HEURISTICS:
        return AgentSpec(name, "heuristic", name)
    if name == ORACLE:
        return AgentSpec(ORACLE_LABEL, "oracle", ORACLE)
    if name in SHIPPED_SAMPLERS:  # a packaged sampler by name, found wherever the package is installed
        from agents.checkpoint import shipped_checkpoint

        with shipped_checkpoint(name) as shipped:
            load_agent_checkpoint(shipped)
            return AgentSpec(name, "checkpoint", str(shipped))
    if name in IN_FRAME_SAMPLERS:
        from agents.adaptive.checkpoint import load_adaptive

        load_adaptive(name)  # a broken installation is reported here, before anything runs
        return AgentSpec(name, IN_FRAME_KIND, name)
    path = Path(name).expanduser()
    looks_like_path = path.suffix in CHECKPOINT_SUFFIXES or os.sep in name or path.exists()
    if not looks_like_path:
        raise ValueError(
            f"unknown agent {name!r}: not a heuristic ({', '.join(HEURISTICS)}), not {ORACLE!r}, not a shipped "
            f"sampler ({', '.join(SHIPPED_SAMPLERS + IN_FRAME_SAMPLERS)}) and not a checkpoint file (.pt or PPO .zip)"
        )
    if not path.is_file():
        raise FileNotFoundError(f"agent {name!r}: no checkpoint at {path}")
    if path.suffix == ".pt":
        from agents.checkpoint import IN_FRAME, resolve_sampler
        from agents.samplers import load_sampler

        if resolve_sampler(path)[0] == IN_FRAME:
            load_sampler(path)  # raises with a clear message on another feature layout
            return AgentSpec(checkpoint_label(path), IN_FRAME_KIND, str(path))
    load_agent_checkpoint(path)  # raises with a clear message on a foreign file or feature layout
    return AgentSpec(checkpoint_label(path), "checkpoint", str(path))


def checkpoint_label(path: Path) -> str:
    """A checkpoint's row label: its file name's stem, or its path when the stem is a shipped sampler's
    name and the file is not that shipped file (a user's own ``ngransac-supervised.pt`` must not pass
    for the shipped sampler)."""
    if path.stem in SHIPPED_SAMPLERS + IN_FRAME_SAMPLERS:
        shipped = shipped_file(path.stem)
        try:
            same = shipped.is_file() and path.resolve() == Path(str(shipped)).resolve()
        except OSError:
            same = False
        if not same:
            return str(path)
    return path.stem


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
        if s.kind in ("checkpoint", IN_FRAME_KIND) and seen[s.label] > 1 and s.source != s.label:
            s = AgentSpec(f"{Path(s.source).parent.name}/{s.label}", s.kind, s.source)
        out.append(s)
    labels = [s.label for s in out]
    dupes = sorted({x for x in labels if labels.count(x) > 1})
    if dupes:
        raise ValueError(f"agent(s) given twice: {', '.join(dupes)}")
    return out


# --------------------------------------------------------------------------- settings


_EVAL_RULES = {
    **{name: Integer(low=1) for name in ("episodes", "frames_per_episode", "budget", "n", "max_iterations")},
    "seed": Integer(low=0),
}
"""The declarations :class:`EvalConfig`'s counts are checked and normalised by (:mod:`stereovo.options`)."""


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
        if not isinstance(self.adaptive_agents, bool):
            raise FieldError("adaptive_agents", f" must be True or False, got {self.adaptive_agents!r}")
        for name, value in check_fields(_EVAL_RULES, vars(self)).items():
            object.__setattr__(self, name, value)
        eps = tuple(float(e) for e in self.epsilons)
        if not eps or not all(0.0 <= e < 1.0 for e in eps) or len(set(eps)) != len(eps):
            raise FieldError("epsilons", f" must be distinct values in [0, 1), got {self.epsilons}")
        object.__setattr__(self, "epsilons", eps)
        budgets = tuple(check_field("budgets", Integer(low=1), b, subject="every budget") for b in self.budgets)
        if not budgets or len(set(budgets)) != len(budgets):
            raise FieldError("budgets", f" must be distinct integers >= 1, got {self.budgets}")
        object.__setattr__(self, "budgets", tuple(sorted(budgets)))
        if not 0.0 <= float(self.sweep_epsilon) < 1.0:
            raise FieldError("sweep_epsilon", f" must be in [0, 1), got {self.sweep_epsilon}")
        object.__setattr__(self, "sweep_epsilon", float(self.sweep_epsilon))
        if self.score_auc is not None:  # the simulator's rule, named here as the field (not the environment's keyword)
            object.__setattr__(self, "score_auc", float(check_field("score_auc", SCORE_AUC, self.score_auc)))
        try:
            object.__setattr__(self, "methods", tuple(normalize_methods(self.methods)))
        except ValueError as err:  # its message names no field: "unknown classical method(s): ..."
            raise FieldError("methods", str(err), subject="") from None
        reserved = {"n_frames", "n_correspondences", "outlier_ratio", "budget"} & set(self.env_kwargs)
        if reserved:
            raise FieldError("env_kwargs", f" must not set {sorted(reserved)}: the evaluation's own options do")
        # A keyword that a field also sets must agree with it: the frames would take one value and the
        # report's header (the config) show the other.
        for key in ("score_auc", "max_iterations"):
            own = getattr(self, key)
            if own is not None and key in self.env_kwargs and self.env_kwargs[key] != own:
                raise ValueError(f"env_kwargs' {key}={self.env_kwargs[key]!r} contradicts {key}={own!r}: set it once")
        object.__setattr__(self, "env_kwargs", dict(self.env_kwargs))

    def env_kwargs_for(self, epsilon: float, budget: int) -> dict[str, Any]:
        # max_iterations caps the adaptive methods (self.max_iterations, equal to a keyword given here):
        # the environment draws a fixed budget and refuses a cap it would not read
        env_kwargs = {key: value for key, value in self.env_kwargs.items() if key != "max_iterations"}
        kwargs = {
            **env_kwargs, "n_frames": self.frames_per_episode, "n_correspondences": self.n,
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


@dataclass
class EvaluationResult:
    """What :func:`agents.evaluation.run.run_evaluation` returns: its inputs, the per-frame rows, their summary
    (:func:`agents.evaluation.report.summarize_evaluation`) and the wall time in seconds."""

    config: EvalConfig
    agents: list[AgentSpec]
    rows: list[dict[str, Any]]
    summary: dict[str, Any]
    wall_s: float


_ROW_INTS = {"budget", "n", "episode", "seed", "frame", "n_inliers", "n_true_inliers", "n_hypotheses", "n_scored",
             "n_point_checks"}
_ROW_STRS = {"method", "kind", "status"}


def parse_row_value(column: str, text: str) -> Any:
    """A ``frames.csv`` cell's value with its type restored (see :data:`ROW_COLUMNS`)."""
    return typed_value(column, text, _ROW_INTS, _ROW_STRS, ("success",), strict=True)
