"""``StereoVOAdaptiveEnv``: in-frame adaptive sampling as a Gymnasium environment.

In :class:`vo_gym.StereoVOEnv` the agent acts once per frame. Here one step is
one small batch of hypotheses *within* a frame: the agent reads what the search
has learnt so far, sets the sampling priors of the next batch and decides when
to stop. The frame's search is the shared loop itself
(:class:`stereovo.estimation.loop.RansacSearch`), stepped one batch at a time
with a sampler that draws from the agent's priors and reports every verified
hypothesis back through the loop's feedback hook.

Which consensus to trust is the agent's call as well: at high contamination a
moving object can outnumber the static inliers, so the largest consensus is
the wrong one. When the frame ends, the hypothesis chosen for refinement is the
one with the largest *belief-weighted* support, ``sum_i w_i [i inlier]`` with
``w = softmax(logit_scale * a)`` the weights of the agent's last action
(uniform logits give the plain largest consensus). The observation carries the
signals that tell a moving object apart: each match's residual under the
previous frame's motion (constant-velocity prediction, a frame feature) and,
globally, how far the best model's motion lies from that prediction.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from stereovo.camera import StereoCamera
from stereovo.compilation import announce_compiling
from stereovo.estimation import EstimatorOptions, StereoProblem, method_spec
from stereovo.estimation.loop import LoopState, RansacSearch
from stereovo.estimation.methods import MotionEstimate
from stereovo.estimation.bansac import WeightedDraw
from stereovo.estimation.termination import FixedBudget
from stereovo.geometry import PoseChain
from stereovo.metrics import frame_metrics
from stereovo.options import Integer, Number
from stereovo.simulation import Frame, Sequence, SimulationConfig
from vo_gym.env import DEFAULT_ESTIMATOR_OPTIONS
from vo_gym.features import FEATURE_BOUND, FEATURE_NAMES, N_FEATURES, compute_features
from vo_gym.rewards import REWARD_MODES, inlier_reward, msac_reward, pose_error_ratio, supervised_reward
from vo_gym.names import keyword_hint

__all__ = ["StereoVOAdaptiveEnv", "LOOP_FEATURE_NAMES", "GLOBAL_FEATURE_NAMES", "ADAPTIVE_FEATURE_NAMES"]

LOOP_FEATURE_NAMES: tuple[str, ...] = ("best_residual", "vote_fraction", "log_votes", "in_best")
"""Per-correspondence columns appended to the frame features (:data:`vo_gym.features.FEATURE_NAMES`):

- ``best_residual``: ``log(1 + e^2 / T^2)`` of the match's squared residual ``e^2`` under the current
  best model, ``T^2`` the estimator's gate (0 before the first hypothesis);
- ``vote_fraction``: share of the frame's scored hypotheses that counted it an inlier;
- ``log_votes``: ``log(1 + count)`` of the same;
- ``in_best``: 1 if it is in the current best model's consensus."""

ADAPTIVE_FEATURE_NAMES: tuple[str, ...] = FEATURE_NAMES + LOOP_FEATURE_NAMES

GLOBAL_FEATURE_NAMES: tuple[str, ...] = (
    "spent", "best_support", "scored_any", "best_cv_rotation", "best_cv_translation", "cv_available", "weighted_best",
)
"""The ``globals`` vector: hypotheses spent / cap; the best model's support / N; 1 once a hypothesis
was scored; ``log(1 + angle / 0.1 deg)`` and ``log(1 + |dt| / 5 cm)`` of the best model's motion against
the previous frame's (constant-velocity prediction; 0 without one); 1 when a previous motion is known;
the belief-weighted support of the hypothesis the frame would end on now, under the last action."""

MASK_ROWS_START = 64  # rows of a frame's mask buffer at first (doubled when a frame scores more)


def _check(rule, name: str, value: Any):
    return rule.check(name, value, prefix="StereoVOAdaptiveEnv: ")


class AgentPriorSampler:
    """The loop's sampler in the adaptive env: guided draws from the agent's current priors; the
    feedback hook records every verified hypothesis of the frame for the observation and the final
    selection."""

    def __init__(self, n: int) -> None:
        self.n = n
        self.weights = np.full(n, 1.0 / n)
        self._sampler = WeightedDraw(self.weights)
        self.votes = np.zeros(n, dtype=np.int64)
        # every scored hypothesis' inlier mask, in order (rows [0, scored)): select() reads them each step
        self._all_masks = np.zeros((MASK_ROWS_START, n), dtype=bool)
        self._scored = 0
        self.R: list[np.ndarray] = []
        self.t: list[np.ndarray] = []
        self.masks: list[np.ndarray] = []
        self.samples: list[np.ndarray] = []
        self.last_samples = np.zeros((0, 3), dtype=np.int64)
        self.last_masks = np.zeros((0, n), dtype=bool)

    def set_weights(self, weights: np.ndarray) -> None:
        """``weights (N,)``: a softmax of bounded logits (all positive and normal), so the draw skips
        ``WeightedSampler``'s validation and gives its samples (:class:`WeightedDraw`)."""
        self.weights = weights
        self._sampler = WeightedDraw(weights)

    def draw(self, batch: int, rng: np.random.Generator) -> np.ndarray:
        return self._sampler.draw(batch, rng)

    def on_hypotheses(self, R, t, inlier_masks, residual_sq, state: LoopState) -> None:
        self.votes += np.count_nonzero(inlier_masks, axis=0)
        self.R.append(R)
        self.t.append(t)
        self.masks.append(inlier_masks)
        self.samples.append(state.samples)
        self.last_samples, self.last_masks = state.samples, inlier_masks
        end = self._scored + inlier_masks.shape[0]
        if end > self._all_masks.shape[0]:
            grown = np.zeros((max(2 * self._all_masks.shape[0], end), self.n), dtype=bool)
            grown[: self._scored] = self._all_masks[: self._scored]
            self._all_masks = grown
        self._all_masks[self._scored:end] = inlier_masks
        self._scored = end

    def all_inlier_probability(self, inliers: np.ndarray) -> float:
        w = self.weights / self.weights.sum()
        inside = float(w[inliers].sum())
        return inside**3

    def n_scored(self) -> int:
        return self._scored

    @property
    def scored_masks(self) -> np.ndarray:
        """``(H, N)`` bool, the inlier masks of every hypothesis scored in this frame, in order."""
        return self._all_masks[: self._scored]

    def select(self, weights: np.ndarray) -> int | None:
        """Index of the scored hypothesis with the largest ``weights``-weighted support."""
        if not self._scored:
            return None
        return int(np.argmax(self.scored_masks @ weights))


class StereoVOAdaptiveEnv(gym.Env):
    """Stereo VO where the agent steers the RANSAC search hypothesis batch by hypothesis batch.

    ## Description

    One episode is one simulated trajectory of ``n_frames`` frame pairs; each frame takes several
    steps. A step draws ``batch_size`` hypotheses from the agent's priors, fits and scores them with
    the shared core (the ``method``'s judge) and returns what the search knows. The frame ends when
    the agent stops (after at least one batch) or at ``max_hypotheses``; then the hypothesis with the
    largest belief-weighted support is refined, the motion is chained into the trajectory (a failed
    estimate keeps the previous motion) and the next frame's observation is returned.

    Registered ids: ``vo_gym/StereoVOAdaptive-v0`` and ``vo_gym/StereoVOAdaptiveHard-v0``
    (:data:`vo_gym.registration.HARD_SETTINGS`).

    ## Action Space

    ``Box(-action_bound, action_bound, (max_correspondences + 1,), float32)``: one logit per
    correspondence slot (sampling weights ``softmax(logit_scale * a)`` over the valid slots, which are
    also the selection weights) and a last slot, stop if ``> 0``. Padding slots are ignored; NaN/inf
    in a valid slot or the stop slot, or a wrong shape, raise ``ValueError``.

    ## Observation Space

    ``Dict(features=Box(-10, 10, (M, F + 4)), mask=MultiBinary(M), globals=Box(-10, 10, (7,)))``:
    the frame features (:data:`vo_gym.features.FEATURE_NAMES`) plus :data:`LOOP_FEATURE_NAMES` per
    correspondence, and :data:`GLOBAL_FEATURE_NAMES`. Never a label.

    ## Rewards

    Each step costs ``hypothesis_cost`` per hypothesis drawn. The step that ends a frame adds the
    frame's reward without that cost (:mod:`vo_gym.rewards`): ``"supervised"`` (success and pose
    error against the truth), ``"inliers"`` or ``"msac"`` (self-supervised, no ground truth).
    A frame's rewards sum to the one-shot environment's reward for the same estimate.

    ## Episode End

    ``terminated`` is always False; ``truncated`` after the last frame's final step.

    ## Info

    Every step: ``frame``, ``frame_hypotheses`` (drawn in this frame so far), ``frame_done``,
    ``batch_samples`` ``(H, 3)`` and ``batch_inliers`` ``(H, N)`` bool of the hypotheses just
    verified (what sampling policies such as BANSAC learn from). On a frame's last step also the
    frame metrics (as :class:`vo_gym.StereoVOEnv`), ``pose_error_ratio``, ``fallback``,
    ``outlier_ratio``, ``stopped`` (the agent stopped, not the cap) and ``all_inlier_drawn`` (a
    scored sample was all static inliers: read from the truth, for the stop's miss rate only).

    ## Arguments

    ``batch_size`` (hypotheses per step, default 4), ``max_hypotheses`` (per-frame cap, default 64),
    ``reward_mode``, ``hypothesis_cost`` (default 0.002), ``success_bonus``, ``failure_reward``,
    ``action_bound`` (default 10), ``logit_scale`` (default 1), ``max_correspondences``; the
    simulator's settings as :class:`vo_gym.StereoVOEnv` (``n_frames``, ``n_correspondences``,
    ``outlier_ratio``, ``outliers`` (``"default"`` / ``"hostile"``), ``outlier_mix``, ``noise_dof``, ``score_auc``, ...); ``method`` (the judge, default
    ``"msac"``) and further estimator options (defaults :data:`vo_gym.env.DEFAULT_ESTIMATOR_OPTIONS`).
    Invalid values raise ``ValueError`` naming the argument.

    ## Version History

    - v0: initial version.
    """

    metadata = {"render_modes": [], "render_fps": 4}

    def __init__(
        self,
        batch_size: int = 4,
        max_hypotheses: int = 64,
        reward_mode: str = "supervised",
        hypothesis_cost: float = 0.002,
        success_bonus: float = 0.5,
        failure_reward: float = -1.0,
        action_bound: float = 10.0,
        logit_scale: float = 1.0,
        max_correspondences: int | None = None,
        preset: str = "car",
        world: str | None = None,
        n_frames: int = 100,
        n_correspondences: int = 500,
        noise_sigma: float = 0.5,
        outlier_ratio: float | tuple[float, float] = 0.5,
        outlier_mix: tuple[float, ...] | dict[str, float] | None = None,
        score_auc: float = 0.75,
        z_min: float = 3.0,
        z_max: float = 60.0,
        camera: StereoCamera | None = None,
        speed: float | None = None,
        outliers: str = "default",
        noise_dof: float | None = None,
        method: str = "msac",
        **estimator_options: Any,
    ) -> None:
        super().__init__()
        self.batch_size = _check(Integer(low=1, high=4096), "batch_size", batch_size)
        self.max_hypotheses = _check(Integer(low=1, high=10**6), "max_hypotheses", max_hypotheses)
        if reward_mode not in REWARD_MODES:
            raise ValueError(f"StereoVOAdaptiveEnv: reward_mode must be one of {list(REWARD_MODES)}, got {reward_mode!r}")
        self.reward_mode = reward_mode
        self.hypothesis_cost = _check(Number(low=0.0, high=1.0), "hypothesis_cost", hypothesis_cost)
        self.success_bonus = _check(Number(low=0.0, high=1.0), "success_bonus", success_bonus)
        self.failure_reward = _check(Number(low=-1.0, high=1.0), "failure_reward", failure_reward)
        self.action_bound = _check(Number(low=0.0, low_open=True, high=300.0), "action_bound", action_bound)
        self.logit_scale = _check(Number(low=0.0, low_open=True, high=300.0), "logit_scale", logit_scale)
        if self.action_bound * self.logit_scale > 300:
            raise ValueError("StereoVOAdaptiveEnv: action_bound * logit_scale must be <= 300 (weights stay representable)")
        try:
            self.sim_config = SimulationConfig(
                preset=preset, world=world, n_frames=n_frames, n_correspondences=n_correspondences,
                noise_sigma=noise_sigma, outlier_ratio=outlier_ratio, outlier_mix=outlier_mix,
                score_auc=score_auc, z_min=z_min, z_max=z_max,
                camera=StereoCamera() if camera is None else camera, speed=speed,
                outliers=outliers, noise_dof=noise_dof,
            )
        except (TypeError, ValueError) as err:
            raise ValueError(f"StereoVOAdaptiveEnv: invalid simulator setting: {err}") from None
        if self.sim_config.noise_sigma <= 0:
            raise ValueError("StereoVOAdaptiveEnv: noise_sigma must be > 0 (the estimator's gates need it)")
        self._sequence_config = dataclasses.replace(self.sim_config, n_frames=self.sim_config.n_frames + 1)
        n = self.n_correspondences = self.sim_config.n_correspondences
        M = self.max_correspondences = n if max_correspondences is None else _check(
            Integer(low=n), "max_correspondences", max_correspondences
        )
        try:
            self._spec = method_spec(method)
            options = {**DEFAULT_ESTIMATOR_OPTIONS, **estimator_options}
            self.estimator_options = EstimatorOptions(noise_sigma=self.sim_config.noise_sigma, **options)
        except (TypeError, ValueError) as err:
            hint = keyword_hint(estimator_options, StereoVOAdaptiveEnv, [f.name for f in dataclasses.fields(EstimatorOptions)])
            raise ValueError(f"StereoVOAdaptiveEnv: invalid estimator setting: {err}{hint}") from None
        self.method = method
        F = N_FEATURES + len(LOOP_FEATURE_NAMES)
        self.observation_space = spaces.Dict({
            "features": spaces.Box(-FEATURE_BOUND, FEATURE_BOUND, shape=(M, F), dtype=np.float32),
            "mask": spaces.MultiBinary(M),
            "globals": spaces.Box(-FEATURE_BOUND, FEATURE_BOUND, shape=(len(GLOBAL_FEATURE_NAMES),), dtype=np.float32),
        })
        self.action_space = spaces.Box(-self.action_bound, self.action_bound, shape=(M + 1,), dtype=np.float32)
        self.feature_names = ADAPTIVE_FEATURE_NAMES
        self._sequence: Sequence | None = None
        self._frame: Frame | None = None
        self._search: RansacSearch | None = None
        self._k = 0

    # ------------------------------------------------------------------ properties

    @property
    def current_frame(self) -> Frame | None:
        """The frame pair being searched (its ``truth`` is for tests, trainers' labels and reports only)."""
        return self._frame

    @property
    def sequence(self) -> Sequence | None:
        """The episode's simulated sequence: its frames depend on the reset seed only."""
        return self._sequence

    @property
    def estimated_poses(self) -> np.ndarray:
        return np.array(self._chain.poses)

    @property
    def scored_inliers(self) -> np.ndarray:
        """``(H, N)`` bool inlier masks of the current frame's scored hypotheses, in drawing order:
        the frame ends on ``argmax_h scored_inliers[h] @ w`` for the last action's weights ``w``."""
        if self._search is None or not self._sampler.masks:
            return np.zeros((0, 0 if self._frame is None else self._frame.n), dtype=bool)
        return np.concatenate(self._sampler.masks)

    @property
    def frame_hypotheses(self) -> int:
        """Hypotheses drawn in the current frame so far."""
        return 0 if self._search is None else self._search.drawn

    # ------------------------------------------------------------------ gymnasium API

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        announce_compiling()  # one line on the first run after installing, else nothing
        self._sequence = Sequence(self._sequence_config, int(self.np_random.integers(0, 2**63 - 1)))
        self._rng = np.random.default_rng(int(self.np_random.integers(0, 2**63 - 1)))
        self._chain = PoseChain(self._sequence.true_poses[0])  # poses and the constant-velocity fallback
        self._successes: list[bool] = []
        self._k = 1
        self._start_frame()
        return self._observation(), {"frame": 1}

    def step(self, action):
        if self._frame is None:
            raise RuntimeError("StereoVOAdaptiveEnv: call reset() before step()")
        if self._k > self.sim_config.n_frames:
            raise RuntimeError("StereoVOAdaptiveEnv: the episode is over (truncated); call reset()")
        logits, stop = self._validate_action(action)
        weights = np.exp(logits - logits.max())
        weights /= weights.sum()
        self._weights = weights
        search, sampler = self._search, self._sampler
        drawn = 0
        stopping = stop and search.scored > 0  # a stop before any scored hypothesis is ignored
        sampler.last_samples, sampler.last_masks = np.zeros((0, 3), dtype=np.int64), np.zeros((0, self._frame.n), bool)
        if not stopping:
            batch = min(self.batch_size, self.max_hypotheses - search.drawn)
            sampler.set_weights(weights)
            before = search.best_score
            search.step(batch)
            drawn = batch
            if search.best_score != before:
                self._best_residual = search.ctx.residuals(search.best_R[None], search.best_t[None])[0]
        reward = -self.hypothesis_cost * drawn
        info: dict[str, Any] = {
            "frame": int(self._frame.index), "frame_hypotheses": int(search.drawn),
            "batch_samples": sampler.last_samples.copy(), "batch_inliers": sampler.last_masks.copy(),
        }
        done = stopping or search.drawn >= self.max_hypotheses
        info["frame_done"] = bool(done)
        truncated = False
        if done:
            reward += self._finish_frame(info, stopped=stopping)
            self._k += 1
            truncated = self._k > self.sim_config.n_frames
            self._start_frame()
        return self._observation(), float(reward), False, truncated, info

    def close(self) -> None:
        self._sequence = None
        self._frame = None

    # ------------------------------------------------------------------ internals

    def _start_frame(self) -> None:
        frame = self._frame = self._sequence.frame(self._k)
        self._problem = StereoProblem.build(
            frame.prev, frame.curr, frame.camera, self.estimator_options.noise_sigma,
            self.estimator_options.min_disparity_sigmas,
        )
        components = self._spec.build(self._problem, self.estimator_options, None, None, {})
        self._sampler = components.sampler = AgentPriorSampler(frame.n)
        components.termination = FixedBudget(self.max_hypotheses)
        # the agent decides when to stop: no stopping rule of the method listens in
        components.listeners = [x for x in components.listeners if not hasattr(x, "required")]
        self._search = RansacSearch(self._problem, components, self._rng)
        self._frame_features = compute_features(
            frame.prev, frame.curr, frame.scores, frame.camera, self.estimator_options.noise_sigma,
            self._chain.last_motion, problem=self._problem,
        )
        self._best_residual = None
        self._weights = np.full(frame.n, 1.0 / frame.n)

    def _finish_frame(self, info: dict[str, Any], stopped: bool) -> float:
        frame, search, sampler = self._frame, self._search, self._sampler
        chosen = sampler.select(self._weights)
        if chosen is not None:
            masks = sampler.scored_masks
            search.choose(np.concatenate(sampler.R)[chosen], np.concatenate(sampler.t)[chosen], masks[chosen].copy(),
                          float(np.count_nonzero(masks[chosen])))
        report = search.finish()
        est = MotionEstimate.from_report(report, self.method, 0.0)
        metrics = frame_metrics(est, frame.truth)
        self._chain.append(est.ok, est.rotation, est.translation)
        self._successes.append(metrics.success)
        info.update({k: v for k, v in metrics.as_dict().items() if k != "time_s"})
        info["pose_error_ratio"] = pose_error_ratio(metrics)
        info["fallback"] = not est.ok
        info["outlier_ratio"] = float(frame.truth.outlier_ratio)
        info["stopped"] = stopped
        samples = np.concatenate(sampler.samples) if sampler.samples else np.zeros((0, 3), dtype=np.int64)
        info["all_inlier_drawn"] = bool(samples.shape[0] and np.any(np.all(frame.truth.inlier[samples], axis=1)))
        if self._k == self.sim_config.n_frames:
            info["success_rate"] = float(np.mean(self._successes))
        if self.reward_mode == "supervised":
            return supervised_reward(metrics, self.success_bonus, 0.0, self.failure_reward)
        if self.reward_mode == "inliers":
            return inlier_reward(est.ok, est.n_inliers, frame.n, 0, 0.0, self.failure_reward)
        return msac_reward(est.ok, est.rotation, est.translation, frame.prev, frame.curr, frame.camera,
                           self.estimator_options.reprojection_threshold_sq, 0, 0.0, self.failure_reward)

    def _validate_action(self, action) -> tuple[np.ndarray, bool]:
        M, n = self.max_correspondences, self._frame.n
        try:
            a = np.asarray(action, dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"StereoVOAdaptiveEnv: the action must be a numeric array of shape ({M + 1},)") from None
        if a.shape != (M + 1,):
            raise ValueError(
                f"StereoVOAdaptiveEnv: the action must have shape ({M + 1},): a logit per slot and the stop slot, "
                f"got {a.shape}"
            )
        valid = np.concatenate([a[:n], a[M:]])
        if not np.all(np.isfinite(valid)):
            raise ValueError("StereoVOAdaptiveEnv: the action has NaN or inf in a valid slot or the stop slot")
        a = np.clip(a, -self.action_bound, self.action_bound)
        return a[:n] * self.logit_scale, bool(a[M] > 0)

    def _observation(self) -> dict[str, np.ndarray]:
        frame, search, sampler = self._frame, self._search, self._sampler
        n, M = frame.n, self.max_correspondences
        scored = sampler.n_scored()
        loop = np.zeros((n, len(LOOP_FEATURE_NAMES)), dtype=np.float64)
        if self._best_residual is not None:
            loop[:, 0] = np.log1p(self._best_residual / search.components.threshold_sq)
            loop[:, 3] = search.best_inliers
        loop[:, 1] = sampler.votes / max(scored, 1)
        loop[:, 2] = np.log1p(sampler.votes)
        features = np.zeros((M, N_FEATURES + len(LOOP_FEATURE_NAMES)), dtype=np.float32)
        features[:n, :N_FEATURES] = self._frame_features
        features[:n, N_FEATURES:] = np.clip(loop, -FEATURE_BOUND, FEATURE_BOUND)
        mask = np.zeros(M, dtype=np.int8)
        mask[:n] = 1
        g = np.zeros(len(GLOBAL_FEATURE_NAMES))
        g[0] = search.drawn / self.max_hypotheses
        g[1] = np.count_nonzero(search.best_inliers) / n
        g[2] = float(scored > 0)
        if self._chain.last_motion is not None:
            g[5] = 1.0
            if scored:
                R_prev, t_prev = self._chain.last_motion
                cos = (np.trace(search.best_R @ R_prev.T) - 1) / 2
                g[3] = math.log1p(math.degrees(math.acos(min(max(cos, -1.0), 1.0))) / 0.1)
                g[4] = math.log1p(float(np.linalg.norm(search.best_t - t_prev)) / 0.05)
        chosen = sampler.select(self._weights)
        if chosen is not None:
            g[6] = float(sampler.scored_masks[chosen] @ self._weights)
        g = np.clip(g, -FEATURE_BOUND, FEATURE_BOUND).astype(np.float32)
        return {"features": features, "mask": mask, "globals": g}

