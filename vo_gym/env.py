"""``StereoVOEnv``: stereo visual odometry as a Gymnasium environment.

An agent watches the putative matches of each frame pair and answers with a
value per match: logits of guided-sampling weights, or scores whose ranking is
the PROSAC order. The shared estimator core (:func:`stereovo.estimation.estimate_motion`)
turns them into a motion under a hypothesis budget; the motion is chained into
a trajectory and rewarded.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from stereovo.camera import StereoCamera
from stereovo.estimation import EstimatorOptions, PreparedEstimator, StereoProblem, drop_unread
from stereovo.estimation.estimator_options import SHARED_OPTIONS
from stereovo.geometry import PoseChain
from stereovo.metrics import KITTI_LENGTHS, KITTI_STEP, FrameMetrics, frame_metrics, trajectory_metrics
from stereovo.options import real_array
from stereovo.simulation import Frame, Sequence
from vo_gym.action_box import ActionBox, clipped_finite, exp_shifted, plain_float_action
from vo_gym.features import FEATURE_BOUND, FEATURE_LAYOUT_VERSION, FEATURE_NAMES, N_FEATURES, compute_features
from vo_gym.names import constructor_keywords
from vo_gym.ordering import descending_order
from vo_gym.rewards import inlier_reward, msac_reward, pose_error_ratio, supervised_reward
from vo_gym.settings import (
    DEFAULT_ESTIMATOR_OPTIONS,
    SAMPLING_MODES,
    check_reset_options,
    check_settings,
    estimator_noise,
    estimator_settings,
    observation_rows,
    read_by_reward,
    simulation_config,
)

__all__ = ["StereoVOEnv", "SAMPLING_MODES", "DEFAULT_ESTIMATOR_OPTIONS"]

# FrameMetrics fields that must not reach info: wall-clock time breaks determinism.
_NON_DETERMINISTIC_METRICS = ("time_s",)
# the info's metrics, in the fields' order (FrameMetrics.as_dict() less those, without building it)
_INFO_METRICS = tuple(f.name for f in dataclasses.fields(FrameMetrics) if f.name not in _NON_DETERMINISTIC_METRICS)


def _nan_to_none(value: Any) -> Any:
    """NaN breaks equality checks of infos (NaN != NaN): 'not available' is reported as None."""
    if isinstance(value, float) and math.isnan(value):
        return None
    return value


def _unscored_rows_failed(frame: Frame) -> Frame:
    """``frame``, or where a match score is NaN or inf, a copy in which those rows are failed matches:
    NaN coordinates (a row without depth, as a front end's failed match: mask 0, never sampled, an
    outlier of every reward) and score 0 (below every real score in (0, 1)). A score that says nothing
    leaves the row nothing to rank it by; its coordinates stay in the source's frame (``sequence``)."""
    scores = frame.scores
    if not (isinstance(scores, np.ndarray) and scores.dtype.kind == "f"):
        return frame  # integers are finite; anything else is the features' to refuse
    finite = np.isfinite(scores)
    if finite.all():
        return frame
    bad = ~finite
    prev, curr = np.array(frame.prev, dtype=float), np.array(frame.curr, dtype=float)
    prev[bad] = np.nan
    curr[bad] = np.nan
    return dataclasses.replace(frame, prev=prev, curr=curr, scores=np.where(finite, scores, 0.0))


def _display_weights(n: int, priors: np.ndarray | None, order: np.ndarray | None) -> np.ndarray:
    """``(n,)`` the weights a rendering colours the matches by: the guided priors scaled to mean 1,
    or the PROSAC order's ranks mapped to 1 (best) .. 0 (worst); empty for a frame without matches."""
    if priors is not None:
        return priors * (n / priors.sum()) if n else priors
    weights = np.empty(n)
    weights[order] = 1.0 - np.arange(n) / max(n - 1, 1)
    return weights


class StereoVOEnv(gym.Env):
    """Stereo visual odometry on a simulated trajectory; the agent proposes RANSAC sampling priors.

    ## Description

    One episode is one simulated trajectory of ``n_frames`` frame pairs
    (:class:`stereovo.simulation.Sequence`); one step is one frame pair
    ``(k-1, k)`` with ``n_correspondences`` putative stereo matches, some of
    them outliers (random mismatches, stereo mismatches, a moving object). The
    agent answers with one value per match; the shared estimator core samples
    minimal sets accordingly under a fixed hypothesis budget, refines the best
    motion on its inliers, and the motion is chained into the estimated
    trajectory (a failed estimate keeps the previous motion: constant-velocity
    fallback).

    Registered ids (``import vo_gym``, or ``"vo_gym:<id>"`` without it):
    ``vo_gym/StereoVO-v0`` (guided), ``vo_gym/StereoVOProsac-v0`` (PROSAC), and
    for benchmarking learned samplers ``vo_gym/StereoVOHard-v0`` /
    ``vo_gym/StereoVOProsacHard-v0``: contamination drawn per frame from
    [0.6, 0.85], 40 % of the outliers on a moving object, match-score AUC 0.6
    (:data:`vo_gym.registration.HARD_SETTINGS`).

    ## Action Space

    ``Box(-action_bound, action_bound, (max_correspondences,), float32)``, one
    value per correspondence slot; slots ``>= n_correspondences`` are padding
    and ignored (their values may even be NaN or inf, e.g. masked logits), and
    so are the slots of matches without depth (``mask`` 0, see below), which the
    estimator never samples. Values outside the Box are clipped to it; NaN/inf
    in a slot whose ``mask`` is 1 or a wrong shape raises ``ValueError``.

    - ``sampling="guided"`` (``vo_gym/StereoVO-v0``): the values are logits;
      the sampling weights are ``softmax(logit_scale * a)`` over the valid
      slots, and each minimal set is three distinct matches drawn in
      proportion to them (guided sampling, Tordoff & Murray).
    - ``sampling="prosac"`` (``vo_gym/StereoVOProsac-v0``): the values are
      scores; ``argsort(-a, stable)`` over the valid slots is the PROSAC order
      (best first).

    ## Observation Space

    ``Dict(features=Box(-10, 10, (max_correspondences, F), float32),
    mask=MultiBinary(max_correspondences))``: row i of ``features`` describes
    match i of the current frame pair with what a real front end knows (match
    score, image coordinates and disparities at k-1 and k, triangulated depth
    and its uncertainty, the reprojection residual under the previous frame's
    estimated motion, the rigid-consistency degree), never its ground-truth
    label; the column layout is :data:`vo_gym.features.FEATURE_NAMES`
    (version :data:`vo_gym.features.FEATURE_LAYOUT_VERSION`). ``mask`` is 1 on
    valid rows and 0 on padding (whose features are 0) and on matches without
    depth (at k-1 or k a coordinate that is not finite, or a disparity at or
    below the camera's ``min_disparity`` or within ``min_disparity_sigmas``,
    default 2, standard deviations of its noise: finite, flagged features, see
    :mod:`vo_gym.features`; the estimator never samples them and treats them as
    outliers). The simulator's frames have such rows too (at the default depths,
    ``z_max`` 60 m, only among their outliers): seldom with
    ``outliers="default"``, often with ``outliers="hostile"``, whose far clutter
    and independent left/right mismatches leave no resolvable disparity (over
    the 21 observations of a seed-0 episode of 20 frames, N = 200,
    ``outlier_ratio=0.8``: 1 such row of 4200 with the default outliers, 554
    with the hostile ones). A row whose match score is NaN or
    inf (a front end's failed match, never the simulator's) is a row without
    depth too: the environment gives it NaN coordinates and score 0
    (:attr:`current_frame`), so it is masked, never sampled and an outlier of
    every reward, and a frame left with too few usable rows fails (status
    ``"failed: ..."``, ``failure_reward``) rather than raising.

    ## Rewards

    Bounded in ``[-1, 1]`` (:mod:`vo_gym.rewards`), chosen by ``reward_mode``:

    - ``"supervised"``: with ``e`` the pose error relative to the success bounds
      (1 deg, max(5 cm, 5 % of the true translation)),
      ``success_bonus * [success] + (1 - success_bonus) * (1 - e) / (1 + e)
      - hypothesis_cost * n_hypotheses``; ``failure_reward`` when the estimate fails.
    - ``"inliers"``: inlier fraction of the chosen model (no ground truth).
    - ``"msac"``: normalised MSAC score ``mean_i max(0, 1 - e_i^2 / T^2)`` of the
      chosen model under the reprojection gate T (no ground truth).

    ## Starting State

    ``reset(seed=...)`` draws a new trajectory and the RANSAC sampler's stream
    from ``self.np_random``: the same seed and the same actions reproduce an
    episode exactly (observations, rewards and infos). The estimated pose
    starts at the true first pose (the identity).

    ## Episode End

    There is no terminal state: ``terminated`` is always False. The episode is
    truncated (``truncated=True``) after ``n_frames`` steps; the observation
    returned then is that of the next frame pair of the same trajectory, so a
    value function can bootstrap from it.

    ## Info

    Every step: ``frame`` (k), the frame's metrics from
    :func:`stereovo.metrics.frame_metrics` without wall time (``rot_err_deg``,
    ``trans_err_m``, ``t_true_norm_m``, ``success``, ``precision``, ``recall``,
    ``n_inliers``, ``n_hypotheses``, ``n_scored``, ``n_point_checks``,
    ``status``), ``pose_error_ratio`` (``e`` above), ``fallback`` (the
    constant-velocity fallback was used) and ``outlier_ratio``: the contamination
    epsilon the simulator drew for the frame (``outlier_ratio``, or its per-frame
    draw from a ``(low, high)`` range), of which the frame holds ``round(epsilon
    N)`` outlier rows, so the realised share ``round(epsilon N) / N`` differs at
    small N (0.99 at N = 3 is three outliers of three); the images environment
    reports the realised share instead (:class:`vo_gym.images_env.StereoVOImagesEnv`).
    At the episode's end also ``trajectory``: the
    :class:`stereovo.metrics.TrajectoryMetrics` fields (unavailable values, e.g.
    KITTI drift on a trajectory shorter than 100 m, are None) plus
    ``success_rate`` and ``failed_frames``. No wall-clock time enters the info
    or the reward.

    ## Arguments

    Environment:

    - ``sampling``: ``"guided"`` (logits -> weights) or ``"prosac"`` (scores -> order).
    - ``reward_mode``: ``"supervised"``, ``"inliers"`` or ``"msac"``.
    - ``max_correspondences``: observation/action rows; None means
      ``n_correspondences``; must be ``>= n_correspondences``.
    - ``action_bound``: the action Box is ``[-action_bound, action_bound]`` (default 10).
    - ``logit_scale``: guided weights are ``softmax(logit_scale * a)`` (default 1);
      e.g. ``action_bound=1, logit_scale=10`` gives an SB3-style ``[-1, 1]`` Box. With
      ``sampling="prosac"`` it must be 1 (no scale changes a ranking), and ``action_bound *
      logit_scale <= 300`` (the softmax's range) binds guided sampling only.
    - ``success_bonus`` in [0, 1] (default 0.5), ``hypothesis_cost`` in [0, 1] per
      hypothesis drawn (default 0.001; a constant under a fixed budget),
      ``failure_reward`` in [-1, 1] (default -1): reward shaping (see Rewards).
    - ``render_mode``: None or ``"rgb_array"`` (the trajectories so far and the
      last frame's matches coloured by the agent's weights).
    - ``kitti_lengths``: segment lengths (m) of the episode-end KITTI drift.

    Simulator (each a :class:`stereovo.simulation.SimulationConfig` field):
    ``preset`` (``"car"``/``"free"``), ``world`` (None, ``"street"``,
    ``"open"``), ``n_frames`` (steps per episode), ``n_correspondences``,
    ``noise_sigma`` (px), ``outlier_ratio`` (a number or a ``(low, high)`` range
    drawn per frame), ``outliers`` (``"default"`` or ``"hostile"``: the preset of
    outlier kinds and noise tail, :data:`stereovo.simulation.OUTLIER_PRESETS`), ``outlier_mix``
    (weights of the outlier kinds; None = the preset's), ``noise_dof`` (Student-t noise; None =
    the preset's), ``score_auc`` (match-score informativeness, 0.5 = useless),
    ``z_min``, ``z_max`` (m), ``camera`` (a StereoCamera; None = KITTI-like),
    ``speed`` (m/frame; None = the preset's).

    Estimator:

    - ``method``: a name from :func:`stereovo.estimation.available_methods` (default ``"msac"``).
    - ``budget``: hypotheses per frame (default 32); None switches to adaptive termination
      (``confidence``, ``max_iterations``).
    - ``batch_size``: hypotheses per vectorised batch; None means ``budget`` (one batch). Given where the
      method sizes its batches itself (``"bansac"`` and ``"p-bansac"`` but under
      ``bansac_update="verdict-likelihood"``, ``"preemptive"``), it is refused (``ValueError``) as an
      option the estimator would not read.
    - ``estimator_noise_sigma``: the pixel noise the estimator and the features assume;
      None uses the simulator's ``noise_sigma`` (which must then be > 0).
    - ``**estimator_options``: any other :class:`~stereovo.estimation.EstimatorOptions` field
      (``threshold_px``, ``gate_probability``, ``polish_iterations``, ``refine``,
      ``refine_iterations``, ``refine_rounds``, ``local_refit``, ``min_inliers``, ``confidence``,
      ``max_iterations``) or an option of the chosen method; the environment's own
      defaults are :data:`DEFAULT_ESTIMATOR_OPTIONS`. An option the estimator would not read
      with the other settings is refused (``ValueError`` naming it, its value and why, by the
      methods' own declarations: :func:`stereovo.estimation.unread_options`): under a fixed
      ``budget`` (the default) ``confidence``, ``max_iterations``, ``first_batch_size`` and ``fail_at_cap`` (the
      budget draws exactly its hypotheses; ``confidence`` stays for the PROSAC stop of
      ``method="prosac"`` and of ``"usac"`` with ``sampling="prosac"``, which picks the
      sampled prefix with it); ``least_squares_refit`` with ``refine=True`` (the default);
      ``gate_probability`` and ``refine_gate_probability`` with a method judged by the
      reprojection gate (``"msac"``, the default, ``"ransac"``, ...), and
      ``refine_gate_probability`` wherever no pixel-gated final refinement runs; ``threshold_px`` with
      a method judged by the 3-D Mahalanobis gate (``"probabilistic"``, ``"mlesac"``, ``"bansac"``, ...)
      unless ``reward_mode="msac"``, whose reward scores under it (the estimator then does not get it).

    Each keyword's rule is declared once, in :mod:`vo_gym.settings`. Invalid values raise
    ``ValueError`` naming the argument; unknown keywords raise ``TypeError``.
    ``reset(options=...)`` takes None or an empty dict; anything else raises ``ValueError``.

    ## Version History

    - v0: initial version (feature layout version 1).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 4}

    def __init__(
        self,
        sampling: str = "guided",
        reward_mode: str = "supervised",
        max_correspondences: int | None = None,
        action_bound: float = 10.0,
        logit_scale: float = 1.0,
        success_bonus: float = 0.5,
        hypothesis_cost: float = 0.001,
        failure_reward: float = -1.0,
        render_mode: str | None = None,
        kitti_lengths: tuple[float, ...] = KITTI_LENGTHS,
        # simulator
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
        # estimator
        method: str = "msac",
        budget: int | None = 32,
        batch_size: int | None = None,
        estimator_noise_sigma: float | None = None,
        **estimator_options: Any,
    ) -> None:
        super().__init__()
        # the messages name the class the user made (the images environment passes its keywords on here)
        owner = type(self).__name__
        s = check_settings(
            owner, sampling=sampling, reward_mode=reward_mode, render_mode=render_mode, action_bound=action_bound,
            logit_scale=logit_scale, success_bonus=success_bonus, hypothesis_cost=hypothesis_cost,
            failure_reward=failure_reward, kitti_lengths=kitti_lengths, max_correspondences=max_correspondences,
            estimator_noise_sigma=estimator_noise_sigma, budget=budget, batch_size=batch_size,
        )
        self.sampling, self.reward_mode, self.render_mode = s["sampling"], s["reward_mode"], s["render_mode"]
        self.action_bound, self.logit_scale = s["action_bound"], s["logit_scale"]
        self.success_bonus, self.hypothesis_cost = s["success_bonus"], s["hypothesis_cost"]
        self.failure_reward, self.kitti_lengths = s["failure_reward"], s["kitti_lengths"]
        self.sim_config = simulation_config(owner, dict(
            preset=preset, world=world, n_frames=n_frames, n_correspondences=n_correspondences,
            noise_sigma=noise_sigma, outlier_ratio=outlier_ratio, outlier_mix=outlier_mix, score_auc=score_auc,
            z_min=z_min, z_max=z_max, camera=camera, speed=speed, outliers=outliers, noise_dof=noise_dof,
        ))
        # One spare frame pair: the observation returned at truncation is the next real frame.
        self._sequence_config = dataclasses.replace(self.sim_config, n_frames=self.sim_config.n_frames + 1)
        self.n_correspondences = self.sim_config.n_correspondences
        self.max_correspondences = observation_rows(owner, s["max_correspondences"], self.n_correspondences)
        self.estimator_noise_sigma = estimator_noise(owner, s["estimator_noise_sigma"], self.sim_config.noise_sigma)
        self.method, self.budget = method, s["budget"]
        self.batch_size = s["batch_size"] if s["batch_size"] is not None else (
            self.budget if self.budget is not None else EstimatorOptions.batch_size)
        fixed = {"noise_sigma": self.estimator_noise_sigma, "budget": self.budget, "batch_size": self.batch_size}
        _, self.estimator_options, extra = estimator_settings(
            owner, StereoVOEnv, method, estimator_options, sampling=self.sampling, fixed=fixed,
            also_known=constructor_keywords(type(self)),  # a subclass's own keywords, for the did-you-mean hints
            reward_mode=self.reward_mode,
            # a batch_size the user gave is refused where the method sizes its batches itself; the default is not
            given_fixed=() if s["batch_size"] is None else ("batch_size",),
        )
        # The options given to the estimator are the ones set here (validated, normalised), not every
        # field: the estimator refuses a given option its method would not read (confidence under the
        # budget, ...), and the others keep the method's defaults, as in estimator_options.
        given = [name for name in (*DEFAULT_ESTIMATOR_OPTIONS, *estimator_options, *fixed) if name in SHARED_OPTIONS]
        kwargs = {**{name: getattr(self.estimator_options, name) for name in given}, **extra}
        # the environment's own settings, and what its reward reads, only where the method reads them too (the
        # user's others were checked above)
        among = (set(kwargs) - set(estimator_options)) | read_by_reward(self.reward_mode)
        self._estimator_kwargs = drop_unread(method, kwargs, among=among, order=self.sampling == "prosac")
        # the method and these options, derived and checked once instead of on every step
        self._estimator = PreparedEstimator(method, **self._estimator_kwargs)

        M = self.max_correspondences
        self.observation_space = spaces.Dict(
            {
                "features": spaces.Box(-FEATURE_BOUND, FEATURE_BOUND, shape=(M, N_FEATURES), dtype=np.float32),
                "mask": spaces.MultiBinary(M),
            }
        )
        self.action_space = ActionBox(-self.action_bound, self.action_bound, shape=(M,), dtype=np.float32)
        self.feature_names = FEATURE_NAMES
        self.feature_layout_version = FEATURE_LAYOUT_VERSION

        self._sequence: Sequence | None = None
        self._ransac_rng: np.random.Generator | None = None
        self._frame: Frame | None = None
        self._problem: StereoProblem | None = None  # the current frame's, built with its observation
        self._k = 0
        self._chain: PoseChain | None = None  # poses, last motion and fallbacks of the episode
        self._successes: list[bool] = []
        self._last_step: dict[str, Any] | None = None

    # ------------------------------------------------------------------ properties

    @property
    def current_frame(self) -> Frame | None:
        """The frame pair the next action applies to (None before ``reset``). Its ``truth`` is for tests and
        oracles only; the observation never reads it. It is the source's frame, except that rows whose
        match score is NaN or inf are failed matches here (NaN coordinates, score 0; see Observation Space)."""
        return self._frame

    @property
    def frame_index(self) -> int:
        """k of the current frame pair (0 before ``reset``)."""
        return self._k

    @property
    def estimated_poses(self) -> np.ndarray:
        """``(k, 4, 4)`` camera-to-world poses estimated so far in this episode (the first is the true start).

        The history is per episode: ``reset`` starts it afresh, so it holds at most ``n_frames + 1``
        poses (128 B each; ``scripts/soak.py`` checks the bound over 10,000 steps)."""
        return np.array(self._chain.poses if self._chain is not None else [])

    @property
    def true_poses(self) -> np.ndarray:
        """``(k, 4, 4)`` true camera-to-world poses of the frames seen so far."""
        if self._sequence is None:
            return np.zeros((0, 4, 4))
        return np.array(self._sequence.true_poses[: len(self._chain.poses)])

    @property
    def sequence(self) -> Sequence | None:
        """The simulated sequence of the current episode (None before the first reset).

        Its frames depend on the reset seed only, never on the actions, so evaluations
        can run classical methods on exactly the frames an agent saw. Their ``truth``
        is ground truth: for reports, never for an agent.
        """
        return self._sequence

    @property
    def estimator_kwargs(self) -> dict[str, Any]:
        """What each step passes to the estimator besides the frame, ``method``, the action and the generator.

        The :class:`~stereovo.estimation.EstimatorOptions` fields the environment sets (its defaults
        :data:`~vo_gym.settings.DEFAULT_ESTIMATOR_OPTIONS`, the user's estimator keywords, ``noise_sigma``,
        ``budget`` and ``batch_size``; of its own, those the method reads: :func:`stereovo.estimation.drop_unread`),
        validated, and the method's own options, as keyword arguments of
        :func:`stereovo.estimation.estimate_motion`; the other fields keep the method's defaults there
        (:attr:`estimator_options` holds them all). A copy: editing it changes nothing in the environment.
        """
        return dict(self._estimator_kwargs)

    # ------------------------------------------------------------------ gymnasium API

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        check_reset_options(type(self).__name__, options)
        super().reset(seed=seed)
        sequence_seed = int(self.np_random.integers(0, 2**63 - 1))
        ransac_seed = int(self.np_random.integers(0, 2**63 - 1))
        self._sequence = self.make_sequence(sequence_seed)
        self._ransac_rng = np.random.default_rng(ransac_seed)
        self._k = 1
        self._frame = _unscored_rows_failed(self._sequence.frame(1))
        self._chain = PoseChain(self._sequence.true_poses[0])
        self._successes = []
        self._last_step = None
        return self._observation(), {"frame": 1}

    def make_sequence(self, seed: int) -> Sequence:
        """The episode's frame sequence for the seed ``reset`` drew (a hook: the images environment,
        :mod:`vo_gym.images_env`, gives rendered or recorded frames instead)."""
        return Sequence(self._sequence_config, seed)

    def step(self, action):
        if self._frame is None:
            raise RuntimeError(f"{type(self).__name__}: call reset() before step()")
        if self._k > self.sim_config.n_frames:
            raise RuntimeError(f"{type(self).__name__}: the episode is over (truncated); call reset()")
        values = self._validate_action(action)
        frame = self._frame
        priors = order = None
        if self.sampling == "guided":
            # np.exp(logits - logits.max()), logits = values * scale; a frame without matches (a blank image)
            # has no weights and no maximum: the estimator fails it as it fails a frame of too few matches
            priors = exp_shifted(values, self.logit_scale) if values.shape[0] else values
        else:
            order = descending_order(values)  # np.argsort(-values, kind="stable"), by radix

        est = self._estimator.estimate(self._problem, priors=priors, order=order, rng=self._ransac_rng)
        metrics = frame_metrics(est, frame.truth)
        self._chain.append(est.ok, est.rotation, est.translation)
        self._successes.append(metrics.success)

        reward = self._reward(est, metrics, frame)
        info: dict[str, Any] = {"frame": int(frame.index)}
        for name in _INFO_METRICS:
            info[name] = getattr(metrics, name)
        info["pose_error_ratio"] = pose_error_ratio(metrics)
        info["fallback"] = not est.ok
        info["outlier_ratio"] = float(frame.truth.outlier_ratio)
        # what render() draws; the weights are worked out there (only a rendering reads them)
        self._last_step = {"frame": frame, "priors": priors, "order": order, "inliers": est.inliers}

        self._k += 1
        truncated = self._k > self.sim_config.n_frames
        if truncated:
            info["trajectory"] = self._trajectory_summary()
        self._frame = _unscored_rows_failed(self._sequence.frame(self._k))
        return self._observation(), reward, False, truncated, info

    def render(self):
        if self.render_mode is None:
            gym.logger.warn(
                f"{type(self).__name__}.render() called without a render_mode; make the env with "
                "render_mode='rgb_array'"
            )
            return None
        if self._frame is None:
            raise RuntimeError(f"{type(self).__name__}: call reset() before render()")
        from vo_gym.rendering import render_rgb

        if self._last_step is None:
            frame, weights, inliers = self._frame, None, None
        else:
            frame, inliers = self._last_step["frame"], self._last_step["inliers"]
            weights = _display_weights(frame.n, self._last_step["priors"], self._last_step["order"])
        return render_rgb(
            self.estimated_poses, self.true_poses, frame, weights, inliers,
            title=f"frame {frame.index}/{self.sim_config.n_frames} ({self.sampling})",
        )

    def close(self) -> None:
        self._sequence = None
        self._frame = None
        self._problem = None

    # ------------------------------------------------------------------ internals

    def _validate_action(self, action) -> np.ndarray:
        # the frame's own count: image frames have fewer matches than slots, the simulator's exactly n
        M, n = self.max_correspondences, self._frame.n if self._frame is not None else self.n_correspondences
        if plain_float_action(action, M):
            # float32 values read as their float64 cast; a NaN or inf takes the checks below
            clipped = clipped_finite(action[:n], self.action_bound)
            if clipped is not None:
                return clipped
        a = real_array("the action", action, (M,), entries="values", per="one value per correspondence slot",
                       what=f"a numeric array of shape ({M},)", prefix=f"{type(self).__name__}: ")
        a = a[:n]
        clipped = clipped_finite(a, self.action_bound)  # np.clip's values, in one pass (the bounds are ordered)
        if clipped is not None:
            return clipped
        # clipped_finite met a NaN or inf: refused in a valid slot
        finite = np.isfinite(a)
        usable = self._problem.usable if self._problem is not None else None
        bad = np.flatnonzero(~finite if usable is None else ~finite & usable)
        if bad.size:
            raise ValueError(
                f"{type(self).__name__}: the action has NaN or inf in {bad.size} valid slot(s) "
                f"(first: slot {int(bad[0])})"
            )
        # only rows without depth (never sampled): any value will do, the lowest keeps the weights finite
        a = np.where(finite, a, -self.action_bound)
        # np.clip's values without its Python wrapper (the bounds are ordered, the values finite)
        return np.minimum(np.maximum(a, -self.action_bound), self.action_bound)

    def _observation(self) -> dict[str, np.ndarray]:
        frame = self._frame
        # Built once per frame: the features read its triangulated points, the step's estimate reuses it.
        self._problem = StereoProblem.build(
            frame.prev, frame.curr, frame.camera, self.estimator_noise_sigma, self.estimator_options.min_disparity_sigmas
        )
        feats = compute_features(
            frame.prev, frame.curr, frame.scores, frame.camera, self.estimator_noise_sigma, self._chain.last_motion,
            problem=self._problem,
        )
        M, n = self.max_correspondences, frame.n
        mask = np.zeros(M, dtype=np.int8)
        mask[:n] = 1 if self._problem.usable is None else self._problem.usable
        if M > n:
            padded = np.zeros((M, N_FEATURES), dtype=np.float32)
            padded[:n] = feats
            feats = padded
        return {"features": feats, "mask": mask}

    def _reward(self, est, metrics, frame: Frame) -> float:
        cost, fail = self.hypothesis_cost, self.failure_reward
        if self.reward_mode == "supervised":
            return supervised_reward(metrics, self.success_bonus, cost, fail)
        if self.reward_mode == "inliers":
            return inlier_reward(est.ok, est.n_inliers, frame.n, est.n_hypotheses, cost, fail)
        return msac_reward(
            est.ok, est.rotation, est.translation, frame.prev, frame.curr, frame.camera,
            self.estimator_options.reprojection_threshold_sq, est.n_hypotheses, cost, fail,
        )

    def _trajectory_summary(self) -> dict[str, Any]:
        est = np.stack(self._chain.poses)
        true = np.asarray(self._sequence.true_poses[: len(est)])
        summary = trajectory_metrics(est, true, kitti_lengths=self.kitti_lengths, kitti_step=KITTI_STEP).as_dict()
        summary = {k: _nan_to_none(v) for k, v in summary.items()}
        summary["success_rate"] = float(np.mean(self._successes))
        summary["failed_frames"] = int(np.count_nonzero(self._chain.fallbacks))
        return summary
