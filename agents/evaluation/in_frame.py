"""The in-frame comparison: success against mean hypotheses per frame on identical frames.

Every sampler runs as a policy of :class:`vo_gym.adaptive_env.StereoVOAdaptiveEnv` (same judge,
same final refinement, same chained motion), on the same held-out episode seeds, so the frames are
identical for all (they depend on the seed only):

- ``learned``: the in-frame sampler of :mod:`agents.adaptive`, its own stop at several confidences;
- ``bansac`` / ``ars``: the samplers of :mod:`stereovo.estimation.methods.bansac` / ``ars`` fed by the env's
  per-hypothesis verdicts, with the match scores or the first one-shot network's weights as priors
  (ARS-MAGSAC's neural guidance), BANSAC's own stop at tau 0.01 (BANSAC) and 0.1 (P-BANSAC),
  ARS's adaptive bound (ARS's deterministic "most probable sample" becomes guided sampling on
  ``p ** 20``, nearly always the most probable points: the env samples, it takes no indices);
- ``ngransac`` / ``ppo`` (one-shot): the shipped samplers' logits on the frame features, fixed budgets
  and the prior-aware stop (the all-inlier chance of one draw from their weights);
- ``uniform`` and ``prosac-score``: uniform logits at fixed budgets; PROSAC by match score (the core's
  ``prosac`` method with its own stop, run on the same frames by :func:`estimate_problem`).

A policy is ``act(obs, step) -> action``, with ``step`` the runner's view of the last env step
(``frame_hypotheses``, ``batch_samples``, ``batch_inliers``, ``new_frame``; the batch's real rows only,
the env's padding cut off).
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from stereovo.estimation import estimate_problem
from stereovo.estimation.methods.ars import baysac_failure_update
from stereovo.estimation.methods.bansac import (
    BANSAC_THRESHOLD,
    P_BANSAC_THRESHOLD,
    BansacSampler,
    initial_beliefs,
)
from stereovo.estimation.loop import LoopState
from stereovo.estimation.problem import StereoProblem
from stereovo.estimation.roles.termination import required_iterations
from stereovo.metrics import frame_metrics
from stereovo.reporting import plot_success, wilson_interval
from vo_gym.adaptive_env import LOOP_FEATURE_NAMES, StereoVOAdaptiveEnv
from vo_gym.features import N_FEATURES, feature_index
from vo_gym.registration import HARD_SETTINGS

LOGIT_BOUND = 10.0
MATCH_SCORE = feature_index("match_score")
IN_BEST = N_FEATURES + LOOP_FEATURE_NAMES.index("in_best")


def _action(logits: np.ndarray, mask: np.ndarray, stop: bool) -> np.ndarray:
    mask = np.asarray(mask, bool)
    out = np.full(mask.shape[0] + 1, -LOGIT_BOUND, dtype=np.float32)
    out[: mask.shape[0]][mask] = np.clip(logits[mask], -LOGIT_BOUND, LOGIT_BOUND)
    out[-1] = 1.0 if stop else -1.0
    return out


class FrameLogitsPolicy:
    """The base of the one-shot samplers' policies: logits ``logits_fn(obs)`` computed at each
    frame's first step and kept for the frame's later steps."""

    def __init__(self, name: str, logits_fn: Callable[[dict], np.ndarray]) -> None:
        self.name, self.logits_fn = name, logits_fn
        self._logits: np.ndarray | None = None

    def frame_logits(self, obs: dict, step: dict) -> np.ndarray:
        if step["new_frame"] or self._logits is None:
            self._logits = self.logits_fn(obs)
        return self._logits


class BudgetPolicy(FrameLogitsPolicy):
    """Fixed logits per frame (``logits_fn(obs)`` at the frame's first step), stop at ``budget``."""

    def __init__(self, name: str, budget: int, logits_fn: Callable[[dict], np.ndarray]) -> None:
        super().__init__(name, logits_fn)
        self.budget = int(budget)

    def act(self, obs: dict, step: dict) -> np.ndarray:
        return _action(self.frame_logits(obs, step), obs["mask"], step["frame_hypotheses"] >= self.budget)


class PriorAwareStopPolicy(FrameLogitsPolicy):
    """A one-shot sampler's fixed logits with the prior-aware stop: stop once
    ``1 - (1 - q)^k >= confidence``, ``q = (sum of the weights of the best model's consensus)^3`` the
    chance that one draw from these weights is three points of that consensus (with replacement)."""

    def __init__(self, name: str, confidence: float, logits_fn: Callable[[dict], np.ndarray]) -> None:
        super().__init__(name, logits_fn)
        self.confidence = float(confidence)

    def act(self, obs: dict, step: dict) -> np.ndarray:
        frame_logits = self.frame_logits(obs, step)
        mask = np.asarray(obs["mask"], bool)
        drawn = step["frame_hypotheses"]
        stop = False
        if drawn:
            logits = np.clip(frame_logits[mask], -LOGIT_BOUND, LOGIT_BOUND)
            w = np.exp(logits - logits.max())
            in_best = np.asarray(obs["features"][mask, IN_BEST]) > 0.5
            q = min(float(w[in_best].sum() / w.sum()) ** 3, 1 - 1e-12)
            stop = q > 0 and drawn >= math.log1p(-self.confidence) / math.log1p(-q)
        return _action(frame_logits, obs["mask"], stop)


def _priors(obs: dict, n: int, logits_fn: Callable[[dict], np.ndarray] | None) -> np.ndarray:
    """Prior weights ``(n,)``: the match scores, or ``exp`` of a network's logits (max-normalised)."""
    if logits_fn is None:
        return np.asarray(obs["features"][:n, MATCH_SCORE], float)
    logits = np.clip(logits_fn(obs)[:n], -LOGIT_BOUND, LOGIT_BOUND)
    return np.exp(logits - logits.max())


class BansacPolicy:
    """BANSAC (the paper's update, :class:`stereovo.estimation.methods.bansac.BansacSampler`; priors: the
    match scores, or a network's weights) updated from each step's verdicts in the order drawn;
    sampling weights ``ceil(100 p)``; its own stop (``#(p < threshold)`` reaches the best consensus'
    outliers, ``threshold`` 0.01 BANSAC, 0.1 P-BANSAC) or the uniform adaptive bound at
    ``confidence``, which the paper's code keeps beside it. ``weights="belief"``: the project's option
    of sampling by ``p`` itself."""

    def __init__(self, confidence: float = 0.99, name: str = "bansac",
                 logits_fn: Callable[[dict], np.ndarray] | None = None, threshold: float = BANSAC_THRESHOLD,
                 weights: str = "discretised") -> None:
        self.name, self.confidence, self.logits_fn, self.threshold = name, float(confidence), logits_fn, float(threshold)
        self.weights = weights
        self._sampler: BansacSampler | None = None

    def act(self, obs: dict, step: dict) -> np.ndarray:
        mask = np.asarray(obs["mask"], bool)
        n = int(mask.sum())
        in_best = np.asarray(obs["features"][:n, IN_BEST]) > 0.5
        if step["new_frame"] or self._sampler is None:
            self._sampler = BansacSampler(n, _priors(obs, n, self.logits_fn), threshold=self.threshold,
                                          weights=self.weights)
        elif step["batch_samples"].shape[0]:
            self._sampler.on_hypotheses(None, None, step["batch_inliers"][:, :n], None,
                                        LoopState(step["frame_hypotheses"], 0.0, samples=step["batch_samples"],
                                                  best_inliers=in_best))
        drawn, n_best = step["frame_hypotheses"], int(np.count_nonzero(in_best))
        stop = drawn > 0 and (self._sampler.stop_rule_met(n_best)
                              or drawn >= required_iterations(n_best, n, self.confidence, 10_000))
        logits = np.zeros(mask.shape[0])
        logits[:n] = np.log(self._sampler.sampling_weights)
        return _action(logits, mask, stop)


class ArsPolicy:
    """ARS's probabilities (priors: the match scores, or a network's weights), BaySAC failure updates,
    adaptive bound."""

    def __init__(self, confidence: float = 0.99, sharpness: float = 20.0, name: str = "ars",
                 logits_fn: Callable[[dict], np.ndarray] | None = None) -> None:
        self.name, self.confidence, self.sharpness, self.logits_fn = name, float(confidence), float(sharpness), logits_fn
        self._p: np.ndarray | None = None
        self._best = -1

    def act(self, obs: dict, step: dict) -> np.ndarray:
        mask = np.asarray(obs["mask"], bool)
        n = int(mask.sum())
        if step["new_frame"] or self._p is None:
            self._p = initial_beliefs(n, _priors(obs, n, self.logits_fn), 0.5, 0.6)
            self._best = -1
        for sample, verdicts in zip(step["batch_samples"], step["batch_inliers"]):
            support = int(verdicts.sum())
            if support > self._best:
                self._best = support
            else:
                self._p = baysac_failure_update(self._p, sample)
        drawn = step["frame_hypotheses"]
        stop = drawn > 0 and drawn >= required_iterations(max(self._best, 0), n, self.confidence)
        logits = np.zeros(mask.shape[0])
        logits[:n] = self.sharpness * np.log(self._p)
        logits[:n] -= logits[:n].max()
        return _action(logits, mask, stop)


class LearnedAdaptivePolicy:
    """:class:`agents.adaptive.policy.AdaptiveSamplerPolicy` in the runner's interface."""

    def __init__(self, policy, name: str) -> None:
        self.policy, self.name = policy, name

    def act(self, obs: dict, step: dict) -> np.ndarray:
        return self.policy.act(obs)


def one_shot_logits(sampler) -> Callable[[dict], np.ndarray]:
    """A shipped one-shot sampler's logits on the frame-feature columns of the adaptive observation."""

    def logits(obs: dict) -> np.ndarray:
        return np.asarray(sampler.act({"features": obs["features"][:, :N_FEATURES], "mask": obs["mask"]}), float)

    return logits


def run_policy(env: StereoVOAdaptiveEnv, policy, seed: int) -> list[dict[str, Any]]:
    """One episode of ``policy``; one row per frame (success, hypotheses, stopped, all-inlier drawn)."""
    obs, _ = env.reset(seed=seed)
    step = {"frame_hypotheses": 0, "batch_samples": np.zeros((0, 3), np.int64),
            "batch_inliers": np.zeros((0, 0), bool), "new_frame": True}
    rows = []
    while True:
        obs, _, _, truncated, info = env.step(policy.act(obs, step))
        count = info["batch_count"]  # the infos are padded to the batch size (StereoVOAdaptiveEnv's Info)
        step = {"frame_hypotheses": 0 if info["frame_done"] else info["frame_hypotheses"],
                "batch_samples": info["batch_samples"][:count], "batch_inliers": info["batch_inliers"][:count],
                "new_frame": info["frame_done"]}
        if info["frame_done"]:
            rows.append({"seed": seed, "frame": info["frame"], "success": bool(info["success"]),
                         "n_hypotheses": int(info["n_hypotheses"]), "stopped": bool(info["stopped"]),
                         "all_inlier_drawn": bool(info["all_inlier_drawn"]),
                         "rot_err_deg": info["rot_err_deg"], "trans_err_m": info["trans_err_m"]})
        if truncated:
            return rows


def run_prosac_by_score(env: StereoVOAdaptiveEnv, seed: int) -> list[dict[str, Any]]:
    """PROSAC ordered by match score (the core's ``prosac`` with its stop) on the episode's frames."""
    env.reset(seed=seed)
    rows = []
    for k in range(1, env.sim_config.n_frames + 1):
        frame = env.sequence.frame(k)
        problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, env.estimator_options.noise_sigma)
        est = estimate_problem(problem, method="prosac", order=np.argsort(-frame.scores, kind="stable"),
                               rng=np.random.default_rng([seed, k]), max_iterations=2000)
        m = frame_metrics(est, frame.truth)
        rows.append({"seed": seed, "frame": k, "success": bool(m.success), "n_hypotheses": int(est.n_hypotheses),
                     "stopped": True, "all_inlier_drawn": None, "rot_err_deg": m.rot_err_deg,
                     "trans_err_m": m.trans_err_m})
    return rows


@dataclass(frozen=True)
class AdaptiveComparison:
    """Settings of the comparison (held-out seeds ``seed .. seed + episodes - 1``)."""

    learned: str = "adaptive-pg-prior"
    confidences: tuple[float, ...] = (0.5, 0.8, 0.9, 0.95, 0.98)
    bansac_thresholds: tuple[float, ...] = (BANSAC_THRESHOLD, P_BANSAC_THRESHOLD)  # BANSAC, P-BANSAC
    budgets: tuple[int, ...] = (4, 8, 16, 32, 64)
    prior_aware_confidences: tuple[float, ...] = (0.9, 0.99)
    one_shot: tuple[str, ...] = ("ngransac-supervised", "ppo")
    episodes: int = 10
    frames_per_episode: int = 10
    seed: int = 5000
    n: int = 500
    max_hypotheses: int = 64
    settings: tuple[tuple[str, float], ...] = (("standard", 0.9), ("hard", 0.8))
    learned_only: bool = False  # the learned rows alone: a candidate checkpoint against the same frames
    part: tuple[int, int] = (0, 1)  # (i, k): the rows whose index is i mod k (PROSAC in the last part)
    extra: dict[str, Any] = field(default_factory=dict)


def make_env(config: AdaptiveComparison, setting: str, epsilon: float) -> StereoVOAdaptiveEnv:
    kwargs = dict(HARD_SETTINGS) if setting == "hard" else {}
    kwargs["outlier_ratio"] = float(epsilon)
    return StereoVOAdaptiveEnv(n_frames=config.frames_per_episode, n_correspondences=config.n,
                               max_hypotheses=config.max_hypotheses, **kwargs)


def policies(config: AdaptiveComparison) -> list[tuple[str, Any, Any]]:
    """``(family, point label, policy)`` for every curve point."""
    from agents.adaptive.checkpoint import load_adaptive
    from agents.adaptive.policy import AdaptiveSamplerPolicy
    from agents.checkpoint import load_sampler

    out: list[tuple[str, Any, Any]] = []
    net, _ = load_adaptive(config.learned)
    for c in config.confidences:
        out.append(("learned (own stop)", c, LearnedAdaptivePolicy(AdaptiveSamplerPolicy(net, c), "learned")))
    if config.learned_only:
        return out
    guide = one_shot_logits(load_sampler(config.one_shot[0]))
    for tau in config.bansac_thresholds:
        out.append(("bansac, score priors (own stop)", tau, BansacPolicy(threshold=tau)))
        out.append((f"bansac, {config.one_shot[0]} priors (own stop)", tau, BansacPolicy(threshold=tau, logits_fn=guide)))
    out.append(("ars, score priors (adaptive bound)", 0.99, ArsPolicy(0.99)))
    out.append((f"ars, {config.one_shot[0]} priors (adaptive bound)", 0.99, ArsPolicy(0.99, logits_fn=guide)))
    for name in config.one_shot:
        logits = one_shot_logits(load_sampler(name))
        for b in config.budgets:
            out.append((f"{name} (one-shot)", b, BudgetPolicy(name, b, logits)))
        for c in config.prior_aware_confidences:
            out.append((f"{name} (one-shot, prior-aware stop)", c, PriorAwareStopPolicy(name, c, logits)))
    for b in config.budgets:
        out.append(("uniform", b, BudgetPolicy("uniform", b, lambda obs: np.zeros(np.asarray(obs["mask"]).shape))))
    return out


def summarise(rows: Sequence[dict[str, Any]]) -> dict[str, Any]:
    success = np.array([r["success"] for r in rows])
    stopped = [r for r in rows if r["stopped"] and r["all_inlier_drawn"] is not None]
    miss = [not r["all_inlier_drawn"] for r in stopped]
    k = int(success.sum())
    return {"frames": len(rows), "success": float(success.mean()), "successes": k,
            "mean_hypotheses": float(np.mean([r["n_hypotheses"] for r in rows])),
            "stopped": len(stopped), "miss_rate": float(np.mean(miss)) if miss else None,
            "success_ci95": [float(b) for b in wilson_interval(k, len(rows))]}


def run_comparison(config: AdaptiveComparison, log: Callable[[str], None] = print) -> dict[str, Any]:
    """Every policy on every setting; returns ``{setting: [{family, point, ...summary}]}``.

    Every row also carries ``order``, its index in the full comparison, so that the parts of a
    comparison split by ``config.part`` (the frames depend on the seeds alone) merge back in order
    (:func:`merge_comparisons`)."""
    result: dict[str, Any] = {"config": {k: v for k, v in config.__dict__.items()}}
    seeds = [config.seed + i for i in range(config.episodes)]
    part, parts = config.part
    for setting, epsilon in config.settings:
        env = make_env(config, setting, epsilon)
        table = []
        todo = policies(config)
        for order, (family, point, policy) in enumerate(todo):
            if order % parts != part:
                continue
            start = time.time()
            rows = [r for s in seeds for r in run_policy(env, policy, s)]
            table.append({"family": family, "point": point, "order": order, **summarise(rows)})
            log(f"{setting} eps {epsilon}: {family} {point}: {table[-1]['success']:.3f} "
                f"at {table[-1]['mean_hypotheses']:.1f} ({time.time() - start:.0f} s)")
        if config.learned_only or part != parts - 1:
            result[f"{setting} eps {epsilon}"] = table
            continue
        rows = [r for s in seeds for r in run_prosac_by_score(env, s)]
        table.append({"family": "prosac by score (own stop)", "point": None, "order": len(todo), **summarise(rows)})
        log(f"{setting} eps {epsilon}: prosac by score: {table[-1]['success']:.3f} at {table[-1]['mean_hypotheses']:.1f}")
        result[f"{setting} eps {epsilon}"] = table
    return result


def merge_comparisons(results: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """One comparison from parts of it (:func:`run_comparison` with ``part``), rows in ``order``; a
    row of a later result replaces an earlier one of the same family and point (a candidate's
    learned rows over a full run's)."""
    merged: dict[str, Any] = {"config": [r.get("config") for r in results]}
    for result in results:
        for key, table in result.items():
            if key == "config":
                continue
            rows = merged.setdefault(key, {})
            for row in table:
                rows[(row["family"], row["point"])] = row
    for key in list(merged):
        if key != "config":
            merged[key] = sorted(merged[key].values(), key=lambda r: r.get("order", math.inf))
    return merged


def comparison_markdown(result: dict[str, Any]) -> str:
    lines = []
    for key, table in result.items():
        if key == "config":
            continue
        lines += [f"### {key}", "", "| sampler | point | success | 95 % CI | mean hypotheses | stop miss rate |",
                  "|---|---|---|---|---|---|"]
        for r in table:
            ci = r["success_ci95"]
            miss = "" if r["miss_rate"] is None else f"{100 * r['miss_rate']:.1f} % of {r['stopped']}"
            point = "" if r["point"] is None else r["point"]
            lines.append(f"| {r['family']} | {point} | {100 * r['success']:.1f} % | {100 * ci[0]:.0f}-{100 * ci[1]:.0f} % "
                         f"| {r['mean_hypotheses']:.1f} | {miss} |")
        lines.append("")
    return "\n".join(lines)


def figure_panels(families: Sequence[str]) -> list[tuple[str, list[str]]]:
    """The two panels of a setting's figure (eight lines at most each for the default rows, as every
    figure of the project; ``tests/test_adaptive_agent.py`` checks it): the learned in-frame sampler
    against the one-shot samplers (a y range zoomed onto them), and against the hand-derived in-frame
    rules (BANSAC, ARS, PROSAC) and uniform sampling."""
    learned = [f for f in families if f.startswith("learned")]
    floor = [f for f in families if f == "uniform"]
    one_shot = [f for f in families if "one-shot" in f]
    rules = [f for f in families if f not in learned + floor + one_shot]
    return [("against the one-shot samplers", learned + one_shot),
            ("against BANSAC, ARS, PROSAC and uniform", learned + rules + floor)]


def write_comparison(result: dict[str, Any], out: str | Path, plots: bool = True) -> list[Path]:
    """``adaptive.json``, ``adaptive.md`` and, with ``plots``, one ``adaptive-<setting>.png`` per
    setting in ``out``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = [out / "adaptive.json", out / "adaptive.md"]
    paths[0].write_text(json.dumps(result, indent=1, default=float))
    paths[1].write_text(comparison_markdown(result))
    if not plots:
        return paths
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    for key, table in result.items():
        if key == "config":
            continue
        families = list(dict.fromkeys(r["family"] for r in table))
        colours = plt.get_cmap("tab20").colors
        styles = {f: {"marker": "os^vD<>ph*"[i % 10], "color": colours[i % len(colours)]} for i, f in enumerate(families)}
        fig, axes = plt.subplots(1, 2, figsize=(13, 4.8))
        for ax, (title, members) in zip(axes, figure_panels(families)):
            lowest = min(r["success_ci95"][0] for r in table if r["family"] in members)
            for family in members:
                pts = sorted((r["mean_hypotheses"], r["success"], r["frames"]) for r in table if r["family"] == family)
                xs, rates, frames = zip(*pts)
                plot_success(ax, xs, rates, frames, family, styles[family])
            ax.set_xscale("log")
            ax.set_ylim(min(5 * math.floor(20 * lowest), 90), 100.5)
            ax.set_xlabel("mean hypotheses per frame")
            ax.set_ylabel("success (%), 95 % Wilson band")
            ax.set_title(f"{key}: {title}")
            ax.grid(alpha=0.3)
            ax.legend(fontsize=7, loc="lower right")
        path = out / f"adaptive-{key.replace(' ', '-')}.png"
        fig.tight_layout()
        fig.savefig(path, dpi=110)
        plt.close(fig)
        paths.append(path)
    return paths


def main(argv: list[str] | None = None) -> int:
    """``python -m agents.evaluation.in_frame --out runs/adaptive``."""
    import argparse

    parser = argparse.ArgumentParser(description="in-frame adaptive sampling comparison")
    parser.add_argument("--out", default="runs/adaptive", help="folder of adaptive.json, the table and the plots")
    parser.add_argument("--learned", default="adaptive-pg-prior",
                        help="the in-frame sampler: a shipped name or an in-frame .pt checkpoint")
    parser.add_argument("--episodes", type=int, default=10, help="episodes a setting")
    parser.add_argument("--frames", type=int, default=10, help="frames an episode")
    parser.add_argument("--seed", type=int, default=5000, help="seed of the first episode (the next ones count up)")
    parser.add_argument("--learned-only", action="store_true", help="run the learned sampler's rows alone")
    parser.add_argument("--part", default="0/1", metavar="I/K", help="run the rows whose index is I mod K")
    parser.add_argument("--setting", action="append", choices=("standard", "hard"),
                        help="run this setting only (repeatable; default: both)")
    parser.add_argument("--merge", nargs="+", metavar="DIR",
                        help="merge the adaptive.json of these folders (later rows win) into --out; runs nothing")
    args = parser.parse_args(argv)
    if args.merge:
        results = [json.loads((Path(d) / "adaptive.json").read_text()) for d in args.merge]
        for path in write_comparison(merge_comparisons(results), args.out):
            print(path)
        return 0
    try:
        part, parts = (int(x) for x in args.part.split("/"))
    except ValueError:
        parser.error(f"--part must be I/K, got {args.part!r}")
    if not 0 <= part < parts:
        parser.error(f"--part I/K needs 0 <= I < K, got {args.part!r}")
    settings = tuple(s for s in AdaptiveComparison().settings if not args.setting or s[0] in args.setting)
    config = AdaptiveComparison(learned=args.learned, episodes=args.episodes, frames_per_episode=args.frames,
                                seed=args.seed, learned_only=args.learned_only, part=(part, parts), settings=settings)
    for path in write_comparison(run_comparison(config), args.out):
        print(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
