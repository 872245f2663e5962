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

from stereovo.estimation import StereoProblem, method_spec
from stereovo.geometry import PoseChain
from stereovo.metrics import FrameMetrics, frame_metrics
from stereovo.options import real_array
from stereovo.simulation import Frame, Sequence
from vo_gym.action_box import ActionBox, clipped_finite, plain_float_action
from vo_gym.step_info import any_all_inlier, padded_batch
from vo_gym.features import FEATURE_BOUND, N_FEATURES, compute_features
from vo_gym.in_frame import (
    ADAPTIVE_FEATURE_NAMES,
    GLOBAL_FEATURE_NAMES,
    LOOP_FEATURE_NAMES,
    AgentPriorSampler,
    InFrameSearch,
)
from vo_gym.rewards import inlier_reward, msac_reward, pose_error_ratio, supervised_reward
from vo_gym.settings import (
    SIMULATOR_KEYWORDS,
    check_reset_options,
    check_settings,
    estimator_noise,
    estimator_settings,
    observation_rows,
    simulation_config,
)

__all__ = [
    "StereoVOAdaptiveEnv", "LOOP_FEATURE_NAMES", "GLOBAL_FEATURE_NAMES", "ADAPTIVE_FEATURE_NAMES", "AgentPriorSampler",
]

# Shared estimator options whose role the agent or the environment's own keywords take here: the
# search's stopping rule is replaced by the agent's stop under max_hypotheses (InFrameSearch), so
# these would be accepted and ignored.
_REFUSED_OPTIONS = {
    "budget": "the agent decides when to stop a frame's search, under the cap max_hypotheses "
              "(a fixed count: max_hypotheses=N with an agent that never stops)",
    "confidence": "the agent decides when to stop a frame's search; no confidence bound runs",
    "max_iterations": "the per-frame cap is the environment's max_hypotheses",
    "first_batch_size": "every step draws the environment's batch_size hypotheses",
    "fail_at_cap": "a frame that reaches max_hypotheses ends on its best-supported hypothesis like any other; "
                   "no stopping rule is there for the cap to come before",
}
_INFO_METRICS = tuple(f.name for f in dataclasses.fields(FrameMetrics) if f.name != "time_s")


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
    error against the truth), ``"inliers"`` or ``"msac"`` (self-supervised, no ground truth),
    ``failure_reward`` for a failed estimate, clipped to [-1, 1].

    So a frame's rewards sum to ``r - hypothesis_cost * H``: ``r`` the reward the one-shot
    environment (:class:`vo_gym.StereoVOEnv`) gives the same estimate at ``hypothesis_cost=0``,
    ``H`` the hypotheses the frame drew. That equals the one-shot reward at this cost only where
    the one-shot environment charges it in full: it charges no cost on a failed frame (its
    reward is ``failure_reward`` flat) and clips its reward, cost included, to [-1, 1], whereas
    here the cost is charged on every frame and outside the clip. The sum therefore lies in
    ``[-1 - hypothesis_cost * max_hypotheses, 1]``, and one step's reward in ``[-1 -
    hypothesis_cost * batch_size, 1]`` (e.g. -1.8 for a failed frame of 8 hypotheses at cost 0.1,
    where the one-shot environment gives -1).

    ## Episode End

    ``terminated`` is always False; ``truncated`` after the last frame's final step.

    ## Info

    Every step: ``frame``, ``frame_hypotheses`` (drawn in this frame so far), ``frame_done``, and
    the hypotheses just verified (what sampling policies such as BANSAC learn from) at a fixed shape,
    so that Gymnasium's vector envs can stack them: ``batch_count`` (H, 0 on a step that stops),
    ``batch_samples`` ``(batch_size, 3)`` int64 whose first H rows are the minimal samples (row
    indices; the rest -1) and ``batch_inliers`` ``(batch_size, max_correspondences)`` bool whose
    ``[:H, :N]`` block holds their inlier masks (the rest False). Read them as
    ``info["batch_samples"][:H]`` and ``info["batch_inliers"][:H, :N]``. On a frame's last step also the
    frame metrics (as :class:`vo_gym.StereoVOEnv`), ``pose_error_ratio``, ``fallback``,
    ``outlier_ratio`` (the contamination epsilon the simulator drew for the frame, as in
    :class:`vo_gym.StereoVOEnv`: the frame holds ``round(epsilon N)`` outlier rows, so the realised
    share differs at small N), ``stopped`` (the agent stopped, not the cap) and ``all_inlier_drawn`` (a
    scored sample was all static inliers: read from the truth, for the stop's miss rate only).

    ## Arguments

    - ``batch_size``: hypotheses per step (default 4; None: ``max_hypotheses``, one step a frame).
    - ``max_hypotheses``: the per-frame cap (default 64).
    - ``reward_mode``, ``success_bonus``, ``failure_reward``, ``action_bound`` (default 10),
      ``logit_scale`` (default 1), ``max_correspondences``, ``estimator_noise_sigma``: as
      :class:`vo_gym.StereoVOEnv`; ``hypothesis_cost`` in [0, 1] (default 0.002).
    - ``method``: the judge (default ``"msac"``).
    - ``render_mode``: None only (Gymnasium's tools pass it): the environment has no renderer, so
      ``metadata["render_modes"]`` is empty and any other mode raises ``ValueError``; ``render()``
      warns and returns None, as Gymnasium's own environments and :class:`vo_gym.StereoVOEnv` do
      without a render mode.
    - ``**settings``: the simulator's settings, the fields of :class:`stereovo.simulation.SimulationConfig`
      with its defaults, as in :class:`vo_gym.StereoVOEnv` (``n_frames``, ``n_correspondences``,
      ``outlier_ratio``, ``outliers`` (``"default"`` / ``"hostile"``), ``outlier_mix``, ``noise_dof``,
      ``score_auc``, ...); any other keyword is an estimator option of ``method`` (defaults
      :data:`vo_gym.settings.DEFAULT_ESTIMATOR_OPTIONS`), except those of the search's stopping rule,
      whose role the agent and the keywords above take: ``budget``, ``confidence``,
      ``max_iterations``, ``first_batch_size`` and ``fail_at_cap`` raise ``TypeError`` saying which.
      An option the judge would not read with the other settings raises ``ValueError`` naming it,
      its value and why, as in :class:`vo_gym.StereoVOEnv` (:func:`stereovo.estimation.unread_options`):
      ``least_squares_refit`` with ``refine=True`` (the default), ``gate_probability`` and
      ``refine_gate_probability`` with ``method="msac"`` (the default), ``threshold_px`` with a method
      judged by the 3-D Mahalanobis gate unless ``reward_mode="msac"`` reads it, ...

    Each keyword's rule is declared once, in :mod:`vo_gym.settings`, and is the same as in
    :class:`vo_gym.StereoVOEnv`. Invalid values raise ``ValueError`` naming the argument; unknown
    keywords raise ``TypeError``. ``reset(options=...)`` takes None or an empty dict; anything else
    raises ``ValueError``.

    ## Version History

    - v0: initial version. ``batch_samples`` / ``batch_inliers`` were ``(H, 3)`` / ``(H, N)`` until
      they were padded to a fixed shape and ``batch_count`` added (the observations, rewards and the
      other infos are unchanged).
    """

    metadata = {"render_modes": [], "render_fps": 4}

    def __init__(
        self,
        batch_size: int | None = 4,
        max_hypotheses: int = 64,
        reward_mode: str = "supervised",
        hypothesis_cost: float = 0.002,
        success_bonus: float = 0.5,
        failure_reward: float = -1.0,
        action_bound: float = 10.0,
        logit_scale: float = 1.0,
        max_correspondences: int | None = None,
        estimator_noise_sigma: float | None = None,
        method: str = "msac",
        render_mode: str | None = None,
        **settings: Any,
    ) -> None:
        super().__init__()
        owner = type(self).__name__  # the messages name the class the user made, also when it is a subclass
        if render_mode is not None:
            raise ValueError(f"{owner}: render_mode must be None (the environment has no renderer: "
                             f"metadata['render_modes'] is empty), got {render_mode!r}")
        self.render_mode = None
        s = check_settings(
            owner, batch_size=batch_size, max_hypotheses=max_hypotheses, reward_mode=reward_mode,
            hypothesis_cost=hypothesis_cost, success_bonus=success_bonus, failure_reward=failure_reward,
            action_bound=action_bound, logit_scale=logit_scale, max_correspondences=max_correspondences,
            estimator_noise_sigma=estimator_noise_sigma,
        )
        self.max_hypotheses, self.reward_mode = s["max_hypotheses"], s["reward_mode"]
        self.batch_size = self.max_hypotheses if s["batch_size"] is None else s["batch_size"]
        self.hypothesis_cost, self.success_bonus = s["hypothesis_cost"], s["success_bonus"]
        self.failure_reward, self.action_bound, self.logit_scale = s["failure_reward"], s["action_bound"], s["logit_scale"]
        self.sim_config = simulation_config(owner, {k: settings.pop(k) for k in SIMULATOR_KEYWORDS if k in settings})
        self._sequence_config = dataclasses.replace(self.sim_config, n_frames=self.sim_config.n_frames + 1)
        n = self.n_correspondences = self.sim_config.n_correspondences
        M = self.max_correspondences = observation_rows(owner, s["max_correspondences"], n)
        self.estimator_noise_sigma = estimator_noise(owner, s["estimator_noise_sigma"], self.sim_config.noise_sigma)
        self._spec, self.estimator_options, self._extra = estimator_settings(
            owner, StereoVOAdaptiveEnv, method, settings, fixed={"noise_sigma": self.estimator_noise_sigma},
            also_known=SIMULATOR_KEYWORDS, refused=_REFUSED_OPTIONS, reward_mode=self.reward_mode,
        )
        # the agent's weights drive the sampler: the judge must need no priors= or order= of its own
        if self._spec.inputs not in ("any", "priors-optional"):
            why = ("needs priors= or order= from its caller" if self._spec.inputs in ("priors", "order")
                   else "draws no hypotheses for the agent to steer")
            raise ValueError(f"{owner}: method {method!r} cannot judge the in-frame search: it {why}; "
                             "judge with a sampling method, e.g. 'msac' (the default), 'mlesac' or 'probabilistic'")
        self.method = method
        F = N_FEATURES + len(LOOP_FEATURE_NAMES)
        self.observation_space = spaces.Dict({
            "features": spaces.Box(-FEATURE_BOUND, FEATURE_BOUND, shape=(M, F), dtype=np.float32),
            "mask": spaces.MultiBinary(M),
            "globals": spaces.Box(-FEATURE_BOUND, FEATURE_BOUND, shape=(len(GLOBAL_FEATURE_NAMES),), dtype=np.float32),
        })
        self.action_space = ActionBox(-self.action_bound, self.action_bound, shape=(M + 1,), dtype=np.float32)
        self.feature_names = ADAPTIVE_FEATURE_NAMES
        self._sequence: Sequence | None = None
        self._frame: Frame | None = None
        self._search: InFrameSearch | None = None
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
        if self._search is None:
            return np.zeros((0, 0 if self._frame is None else self._frame.n), dtype=bool)
        return self._search.scored_inliers

    @property
    def frame_hypotheses(self) -> int:
        """Hypotheses drawn in the current frame so far."""
        return 0 if self._search is None else self._search.drawn

    @property
    def method_options(self) -> dict[str, Any]:
        """The judging method's own options (``method_spec(method).extra_options``), validated: the given
        ones over their declared defaults, as each frame's search reads them (a copy)."""
        return dict(self._extra)

    # ------------------------------------------------------------------ gymnasium API

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        check_reset_options(type(self).__name__, options)
        super().reset(seed=seed)
        self._sequence = Sequence(self._sequence_config, int(self.np_random.integers(0, 2**63 - 1)))
        self._rng = np.random.default_rng(int(self.np_random.integers(0, 2**63 - 1)))
        self._chain = PoseChain(self._sequence.true_poses[0])  # poses and the constant-velocity fallback
        self._successes: list[bool] = []
        self._k = 1
        self._start_frame()
        return self._observation(), {"frame": 1}

    def step(self, action):
        if self._frame is None:
            raise RuntimeError(f"{type(self).__name__}: call reset() before step()")
        if self._k > self.sim_config.n_frames:
            raise RuntimeError(f"{type(self).__name__}: the episode is over (truncated); call reset()")
        logits, stop = self._validate_action(action)
        search = self._search
        drawn, stopping, done = search.step(logits, stop, self.batch_size)
        reward = -self.hypothesis_cost * drawn
        info: dict[str, Any] = {"frame": int(self._frame.index), "frame_hypotheses": int(search.drawn)}
        info.update(self._batch_info(search.sampler.last_samples, search.sampler.last_masks))
        info["frame_done"] = bool(done)
        truncated = False
        if done:
            reward += self._finish_frame(info, stopped=stopping)
            self._k += 1
            truncated = self._k > self.sim_config.n_frames
            self._start_frame()
        return self._observation(), float(reward), False, truncated, info

    def __getstate__(self) -> dict[str, Any]:
        # the judge by name: the registry's method specs hold local functions, which do not pickle
        # (stereovo.estimation.PreparedEstimator pickles its method the same way)
        state = dict(self.__dict__)
        state["_spec"] = self._spec.name
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        state = dict(state)
        state["_spec"] = method_spec(state["_spec"])
        self.__dict__.update(state)

    def render(self) -> None:
        """Nothing to draw: warns (Gymnasium's logger) and returns None, as a Gymnasium environment made
        without a render mode does; the environment has no renderer (``render_mode`` is always None)."""
        gym.logger.warn(f"{type(self).__name__}.render() called without a render_mode: the environment has no renderer "
                        "(metadata['render_modes'] is empty), so there is nothing to draw")
        return None

    def close(self) -> None:
        self._sequence = None
        self._frame = None

    # ------------------------------------------------------------------ internals

    def _start_frame(self) -> None:
        frame = self._frame = self._sequence.frame(self._k)
        problem = StereoProblem.build(
            frame.prev, frame.curr, frame.camera, self.estimator_options.noise_sigma,
            self.estimator_options.min_disparity_sigmas,
        )
        features = compute_features(
            frame.prev, frame.curr, frame.scores, frame.camera, self.estimator_options.noise_sigma,
            self._chain.last_motion, problem=problem,
        )
        self._search = InFrameSearch(problem, features, self._spec, self.estimator_options, self.max_hypotheses,
                                     self._chain.last_motion, self._rng, self._extra)

    def _finish_frame(self, info: dict[str, Any], stopped: bool) -> float:
        frame, search = self._frame, self._search
        est = search.finish(self.method)
        metrics = frame_metrics(est, frame.truth)
        self._chain.append(est.ok, est.rotation, est.translation)
        self._successes.append(metrics.success)
        for name in _INFO_METRICS:  # the metrics but their wall time, as the step environment's info
            info[name] = getattr(metrics, name)
        info["pose_error_ratio"] = pose_error_ratio(metrics)
        info["fallback"] = not est.ok
        info["outlier_ratio"] = float(frame.truth.outlier_ratio)
        info["stopped"] = stopped
        info["all_inlier_drawn"] = any_all_inlier(search.all_samples(), frame.truth.inlier)
        if self._k == self.sim_config.n_frames:
            info["success_rate"] = float(np.mean(self._successes))
        if self.reward_mode == "supervised":
            return supervised_reward(metrics, self.success_bonus, 0.0, self.failure_reward)
        if self.reward_mode == "inliers":
            return inlier_reward(est.ok, est.n_inliers, frame.n, 0, 0.0, self.failure_reward)
        return msac_reward(est.ok, est.rotation, est.translation, frame.prev, frame.curr, frame.camera,
                           self.estimator_options.reprojection_threshold_sq, 0, 0.0, self.failure_reward)

    def _batch_info(self, samples: np.ndarray, masks: np.ndarray) -> dict[str, Any]:
        """The step's hypotheses at a fixed shape (see Info): ``batch_count`` real rows, then padding."""
        count = int(samples.shape[0])
        batch_samples = np.empty((self.batch_size, 3), dtype=np.int64)
        batch_inliers = np.empty((self.batch_size, self.max_correspondences), dtype=bool)
        if samples.dtype == np.int64 and masks.dtype == np.bool_ and samples.ndim == masks.ndim == 2 \
                and samples.shape[1] == 3 and masks.shape[0] == count <= self.batch_size \
                and masks.shape[1] <= self.max_correspondences:
            padded_batch(samples, masks, batch_samples, batch_inliers)  # the two fills and copies in one pass
        else:
            batch_samples.fill(-1)
            batch_samples[:count] = samples
            batch_inliers.fill(False)
            batch_inliers[:count, : masks.shape[1]] = masks
        return {"batch_samples": batch_samples, "batch_inliers": batch_inliers, "batch_count": count}

    def _validate_action(self, action) -> tuple[np.ndarray, bool]:
        M, n = self.max_correspondences, self._frame.n
        if plain_float_action(action, M + 1):
            a = action  # the clip reads float32 values as the float64 ones real_array's cast would give
        else:
            a = real_array("the action", action, (M + 1,), entries="values", per="a logit per slot and the stop slot",
                           what=f"a numeric array of shape ({M + 1},)", prefix=f"{type(self).__name__}: ")
        # np.clip's values on the slots read (the others are ignored), times the logit scale; clipping
        # keeps the stop's sign
        logits = clipped_finite(a[:n], self.action_bound, self.logit_scale)
        if logits is None or not math.isfinite(a[M]):
            raise ValueError(f"{type(self).__name__}: the action has NaN or inf in a valid slot or the stop slot")
        return logits, bool(a[M] > 0)

    def _observation(self) -> dict[str, np.ndarray]:
        return self._search.observation(self.max_correspondences)
