"""NG-RANSAC-style policy-gradient training of the per-correspondence sampler.

Brachmann & Rother, "Neural-guided RANSAC", ICCV 2019 (docs/algorithms.md, "Learned samplers"): the network gives a
distribution p over correspondences; a pool of M minimal samples drawn from p
goes through the shared RANSAC core under the same fixed budget as the
environment, and the expected task loss is minimised with the score-function
gradient ``E[(loss - b) grad log p(pool)]``, ``b`` the mean loss of the K pools
drawn for the same frame.

Samples are drawn sequentially without replacement (the core's
``WeightedSampler``), so ``log p(pool)`` is the sum over its triplets of the
ordered-draw log-probability, computed here in torch to be differentiated.

Frames come from simulated sequences, and features from
``vo_gym.features.compute_features`` with the previous frame's estimated motion,
exactly as the environment computes them.
"""

from __future__ import annotations

import copy
import dataclasses
import itertools
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np
import torch

from agents.checkpoint import load_checkpoint, save_checkpoint
from agents.network import CorrespondenceNet
from agents.network_size import MAX_NETWORK_PARAMETERS, MAX_NETWORK_SIZE, correspondence_net_parameters
from agents.training_limits import LEARNING_RATE, MAX_TRAINING_STEPS
from stereovo.estimation import (
    EstimatorOptions,
    MotionEstimate,
    ReplaySampler,
    StereoProblem,
    WeightedSampler,
    method_spec,
    run_ransac,
)
from stereovo.estimation.estimator_options import MAX_COUNT
from stereovo.geometry import rotation_error
from stereovo.metrics import pose_error_ratio
from stereovo.options import Integer, Number, Option, value_repr
from stereovo.simulation import OUTLIER_KINDS, Frame, Sequence, SimulationConfig
from stereovo.simulation.config import MAX_CORRESPONDENCES, MAX_FRAMES
from vo_gym.settings import DEFAULT_ESTIMATOR_OPTIONS, FieldError, check_fields
from vo_gym.features import N_FEATURES, compute_features

LOSSES = ("supervised", "self-supervised", "self-supervised-smooth")
LOSS_CAP = 4.0  # a pose that misses the success region by 4x or more all counts the same

_NGRANSAC_RULES: dict[str, Option] = {
    # counts within the caps of the estimator (hypotheses), the simulator (matches, frames) and
    # agents.training_limits (training length, evaluations), so that a typo fails here, naming the field
    "budget": Integer(low=1, high=MAX_COUNT),
    "pools": Integer(low=1, high=MAX_COUNT),
    "n_correspondences": Integer(low=3, high=MAX_CORRESPONDENCES),
    "frames_per_sequence": Integer(low=1, high=MAX_FRAMES),
    **{name: Integer(low=1, high=MAX_TRAINING_STEPS) for name in ("frames", "eval_every", "eval_frames")},
    "seed": Integer(low=0),
    "learning_rate": LEARNING_RATE,
    "eval_epsilon": Number(low=0.0, high=1.0, high_open=True),
}
"""The declarations :class:`NGRansacConfig`'s numbers are checked and normalised by (:mod:`stereovo.options`)."""

RESUMABLE_FIELDS = ("frames", "seed", "eval_every")
"""The config fields a resumed run may change (:meth:`NGRansacTrainer.resume`): how long to train
(``frames``, the new total), the seed of the continuation and the evaluation period. The others are
the run's: its network, loss, budget, pools, learning rate (the optimiser's state carries it),
simulated training frames (contamination, matches, sequence length) and evaluation size (its history
compares the evaluations)."""


@dataclass
class NGRansacConfig:
    """Training settings (saved in every checkpoint).

    Attributes:
        loss: "supervised" (pose error against ground truth), "self-supervised" (-inliers / N) or
            "self-supervised-smooth" (-inliers / N plus a penalty on the change from the previous
            frame's estimated motion: a vehicle's motion is smooth, a moving object's consensus is
            not the camera's; still no ground truth).
        epsilon_range: contamination drawn per frame.
        budget: hypotheses per pool (M), the environment's budget (at most
            :data:`~stereovo.estimation.estimator_options.MAX_COUNT`).
        pools: pools per frame (K, at least 2); their mean loss is the baseline.
        frames: training frames (policy-gradient steps; at most
            :data:`~agents.training_limits.MAX_TRAINING_STEPS`, as are ``eval_every`` and ``eval_frames``).
        learning_rate: Adam's step size, in ``(0, 0.1)`` (:data:`~agents.training_limits.MAX_LEARNING_RATE`).
        method: core method that fits and scores each pool.
        max_grad_norm: the policy gradient's norm is clipped to this (None: no clipping). One
            outsized step can push the softmax onto a few points whose triplets all fail; then
            every pool has the same loss, the advantage is zero and training never recovers.
        entropy_weight: weight of the sampling distribution's entropy (normalised by log N)
            subtracted from the objective, which keeps the mass from collapsing onto a few points.
        domain_randomisation: each training sequence draws its own outlier process, noise tail
            and score AUC (:func:`randomised_frame_stream`) instead of ``outlier_mix`` and
            ``score_auc``; the held-out evaluations stay on the fixed setting.
    """

    loss: str = "supervised"
    epsilon_range: tuple[float, float] = (0.3, 0.9)
    n_correspondences: int = 500
    noise_sigma: float = 0.5
    score_auc: float = 0.75
    outlier_mix: tuple[float, float, float] = (0.6, 0.2, 0.2)
    # Short sequences, as in `vo-gym evaluate` (10-frame episodes): every sequence's first frame
    # has no constant-velocity prediction, the hardest case, and training must see enough of them.
    frames_per_sequence: int = 10
    budget: int = 11  # the agents' target budget: 99 % success within 575 / 50 hypotheses
    pools: int = 8
    frames: int = 16000
    learning_rate: float = 1e-4
    width: int = 64
    blocks: int = 3
    method: str = "msac"  # the environment's default core method
    seed: int = 0
    eval_every: int = 1000
    eval_frames: int = 300
    eval_epsilon: float = 0.8
    keep_best: bool = True  # end with the weights that evaluated best, not the last ones
    max_grad_norm: float | None = 5.0
    entropy_weight: float = 0.0
    domain_randomisation: bool = False

    def __post_init__(self) -> None:
        if self.loss not in LOSSES:
            raise FieldError("loss", f" must be one of {LOSSES}, got {self.loss!r}")
        lo, hi = self.epsilon_range
        if not 0 <= lo <= hi < 1:
            raise FieldError("epsilon_range", f" must satisfy 0 <= low <= high < 1, got {self.epsilon_range}")
        for name, value in check_fields(_NGRANSAC_RULES, vars(self)).items():
            setattr(self, name, value)
        for name in ("width", "blocks"):
            if getattr(self, name) < 1:
                raise FieldError(name, f" must be >= 1, got {getattr(self, name)}")
        # a network a checkpoint can hold (agents.checkpoint refuses larger ones at load)
        for name in ("width", "blocks"):
            if getattr(self, name) > MAX_NETWORK_SIZE:
                raise FieldError(name, f" must be <= {MAX_NETWORK_SIZE}, got {getattr(self, name)}")
        count = correspondence_net_parameters(N_FEATURES, self.width, self.blocks)
        if count > MAX_NETWORK_PARAMETERS:
            raise FieldError("width", f" {self.width} and blocks {self.blocks} make a network of {count:,} "
                             f"parameters, more than the {MAX_NETWORK_PARAMETERS:,} a checkpoint may hold")
        if self.max_grad_norm is not None and not self.max_grad_norm > 0:
            raise FieldError("max_grad_norm", f" must be None or > 0, got {self.max_grad_norm}")
        if not self.entropy_weight >= 0:
            raise FieldError("entropy_weight", f" must be >= 0, got {self.entropy_weight}")
        if self.pools < 2:
            raise FieldError("pools", " must be >= 2: the baseline is the mean loss of the pools")
        self.epsilon_range = (float(lo), float(hi))

    def simulation(self, epsilon: float | tuple[float, float] | None = None) -> SimulationConfig:
        return SimulationConfig(
            n_frames=self.frames_per_sequence,
            n_correspondences=self.n_correspondences,
            noise_sigma=self.noise_sigma,
            outlier_ratio=self.epsilon_range if epsilon is None else epsilon,
            outlier_mix=self.outlier_mix,
            score_auc=self.score_auc,
        )


def frame_stream(config: SimulationConfig, seed: int) -> Iterator[Frame]:
    """Frames of consecutive sequences (the episode structure the environment uses)."""
    for i in itertools.count():
        yield from Sequence(config, seed=np.random.SeedSequence([seed, i]))


RANDOMISED_AUC = (0.55, 0.9)
RANDOMISED_DOF = (3.0, 12.0)


def randomised_frame_stream(config: "NGRansacConfig", seed: int) -> Iterator[Frame]:
    """Frames of consecutive sequences, each sequence with its own match-error process (domain
    randomisation): the outlier kinds' weights drawn from a flat Dirichlet over every kind of
    :data:`stereovo.simulation.OUTLIER_KINDS` (the hostile preset's kinds included), Student-t
    pixel noise with ``dof ~ U(3, 12)`` on half the sequences (Gaussian on the others, scale
    ``config.noise_sigma`` throughout: the features and gates assume a known sensor noise) and the
    score AUC from ``U(0.55, 0.9)``; contamination from ``config.epsilon_range`` per frame."""
    rng = np.random.default_rng([seed, 17])
    base = config.simulation()
    for i in itertools.count():
        sim = dataclasses.replace(base, **randomised_settings(rng))
        yield from Sequence(sim, seed=np.random.SeedSequence([seed, i]))


def randomised_settings(rng: np.random.Generator) -> dict[str, Any]:
    """One randomised sequence's match-error process as :class:`SimulationConfig` fields:
    ``outlier_mix`` (flat Dirichlet weights over :data:`stereovo.simulation.OUTLIER_KINDS`),
    ``noise_dof`` (``U(3, 12)`` on half the draws, else None: Gaussian) and ``score_auc``
    (``U(0.55, 0.9)``), drawn from ``rng`` in that order. The in-frame trainer draws its
    randomised episodes from it too (``AdaptiveTrainConfig.domain_randomisation``)."""
    mix = dict(zip(OUTLIER_KINDS, rng.dirichlet(np.ones(len(OUTLIER_KINDS))).tolist()))
    dof = float(rng.uniform(*RANDOMISED_DOF)) if rng.random() < 0.5 else None
    auc = float(rng.uniform(*RANDOMISED_AUC))
    return {"outlier_mix": mix, "noise_dof": dof, "score_auc": auc}


def pose_loss(estimate: MotionEstimate, frame: Frame) -> float:
    """Supervised task loss: the pose error in units of the success thresholds, capped.

    ``< 1`` exactly when the frame counts as a success.
    """
    if not estimate.ok:
        return LOSS_CAP
    r_deg = float(np.degrees(rotation_error(estimate.rotation, frame.truth.rotation)))
    t_true = float(np.linalg.norm(frame.truth.translation))
    t_err = float(np.linalg.norm(estimate.translation - frame.truth.translation))
    return min(pose_error_ratio(r_deg, t_err, t_true), LOSS_CAP)


def inlier_loss(estimate: MotionEstimate, frame: Frame, previous_motion=None) -> float:
    """Self-supervised task loss: minus the inlier fraction of the chosen model (no ground truth)."""
    return -estimate.n_inliers / max(frame.n, 1)


SMOOTHNESS_WEIGHT = 0.5
SMOOTHNESS_SCALE_M = 0.25  # a change of 25 cm/frame in translation costs the full weight
SMOOTHNESS_SCALE_DEG = 1.0


def smooth_inlier_loss(estimate: MotionEstimate, frame: Frame, previous_motion=None) -> float:
    """Inlier loss plus a capped penalty on the change from the previous estimated motion."""
    loss = inlier_loss(estimate, frame)
    if previous_motion is None or not estimate.ok:
        return loss
    R_prev, t_prev = previous_motion
    change = float(np.linalg.norm(estimate.translation - t_prev)) / SMOOTHNESS_SCALE_M
    change += float(np.degrees(rotation_error(estimate.rotation, R_prev))) / SMOOTHNESS_SCALE_DEG
    return loss + SMOOTHNESS_WEIGHT * min(change, 1.0)


def _pose_loss(estimate: MotionEstimate, frame: Frame, previous_motion=None) -> float:
    return pose_loss(estimate, frame)


LOSS_FUNCTIONS = {"supervised": _pose_loss, "self-supervised": inlier_loss, "self-supervised-smooth": smooth_inlier_loss}


def run_pool(problem: StereoProblem, samples: np.ndarray, method: str, options: EstimatorOptions, rng: np.random.Generator) -> MotionEstimate:
    """Fit, score and refine exactly ``samples`` with a core method (fixed budget = len(samples))."""
    spec = method_spec(method)
    if spec.build is None:
        raise ValueError(f"method {method!r} is not a sampling method and cannot train a sampler")
    components = spec.build(problem, options, None, None, {})
    components.sampler = ReplaySampler(samples, problem.n)
    start = time.perf_counter()
    report = run_ransac(problem, components, rng)
    return MotionEstimate.from_report(report, method, time.perf_counter() - start)


def ordered_triplet_log_prob(log_p: torch.Tensor, samples: torch.Tensor) -> torch.Tensor:
    """Log-probability ``(S,)`` of ordered triplets drawn sequentially without replacement from ``p``."""
    picked = log_p[samples]  # (S, 3)
    p = picked.exp()
    taken = torch.cumsum(p, dim=1) - p
    return (picked - torch.log1p(-taken.clamp(max=1 - 1e-6))).sum(dim=1)


@dataclass
class TrainingLog:
    step: int
    mean_loss: float
    success_rate: float  # of the pools' estimates in this reporting window
    eval_success: float | None = None
    grad_norm: float | None = None  # median policy-gradient norm (before clipping) in the window


@dataclass
class NGRansacTrainer:
    """Policy-gradient trainer. ``train()`` runs ``config.frames`` steps and returns the network
    with the weights that scored best in the periodic evaluations (held-out seeds)."""

    config: NGRansacConfig
    net: CorrespondenceNet | None = None
    on_log: Callable[[TrainingLog], None] | None = None
    step: int = 0
    history: list[TrainingLog] = field(default_factory=list)
    best_eval: float = -1.0
    best_state: dict | None = None

    def __post_init__(self) -> None:
        torch.manual_seed(self.config.seed)
        if self.net is None:
            self.net = CorrespondenceNet(N_FEATURES, self.config.width, self.config.blocks)
        self.optimizer = torch.optim.Adam(self.net.parameters(), lr=self.config.learning_rate)
        self.rng = np.random.default_rng(self.config.seed)
        # The environment's estimator settings, so a policy trained here behaves the same in the env.
        self.options = EstimatorOptions(
            noise_sigma=self.config.noise_sigma, budget=self.config.budget, batch_size=self.config.budget,
            **DEFAULT_ESTIMATOR_OPTIONS,
        )
        self.loss_fn = LOSS_FUNCTIONS[self.config.loss]

    def frame_loss(self, frame: Frame, previous_motion=None) -> tuple[torch.Tensor, list[float], list[bool], MotionEstimate]:
        """The objective one training step on ``frame`` descends, without the step: ``(objective, losses,
        success, first)``, the policy-gradient objective (minus the entropy bonus), each pool's task loss,
        whether each pool's pose is a success, and the first pool's estimate. ``previous_motion`` (R, t) is
        the prediction the features and the smooth loss read (None: the first frame of a sequence).
        Draws the pools from the trainer's generator, as a step does."""
        return self._frame_loss(frame, previous_motion)

    def _frame_loss(self, frame: Frame, previous_motion) -> tuple[torch.Tensor, list[float], list[bool], MotionEstimate]:
        feats = compute_features(frame.prev, frame.curr, frame.scores, frame.camera, frame.noise_sigma, previous_motion)
        problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
        x = torch.from_numpy(feats)[None]
        mask = torch.ones(1, frame.n, dtype=torch.bool)
        log_p = torch.log_softmax(self.net(x, mask)[0], dim=0)
        sampler = WeightedSampler(log_p.detach().exp().double().numpy())
        K, M = self.config.pools, self.config.budget
        samples = sampler.draw(K * M, self.rng)
        log_prob = ordered_triplet_log_prob(log_p, torch.from_numpy(samples)).view(K, M).sum(dim=1)
        estimates = [run_pool(problem, samples[k * M : (k + 1) * M], self.config.method, self.options, self.rng) for k in range(K)]
        losses = [self.loss_fn(e, frame, previous_motion) for e in estimates]
        success = [pose_loss(e, frame) < 1.0 for e in estimates]
        advantage = torch.tensor(losses) - float(np.mean(losses))
        objective = (advantage * log_prob).mean()
        if self.config.entropy_weight > 0:
            entropy = -(log_p.exp() * log_p).sum() / float(np.log(max(frame.n, 2)))
            objective = objective - self.config.entropy_weight * entropy
        return objective, losses, success, estimates[0]

    def train(self, frames: int | None = None, progress: bool = False) -> CorrespondenceNet:
        from tqdm import tqdm

        frames = self.config.frames if frames is None else frames
        seed = self.config.seed * 7919 + self.step
        if self.config.domain_randomisation:
            stream = randomised_frame_stream(self.config, seed)
        else:
            stream = frame_stream(self.config.simulation(), seed)
        previous_motion = None
        window_loss, window_success, window_norm = [], [], []
        self.net.train()
        bar = tqdm(total=frames, desc=f"ngransac ({self.config.loss})", disable=not progress, unit="frame")
        for i in range(frames):
            frame = next(stream)
            if frame.index == 1:
                previous_motion = None  # a new sequence: no constant-velocity prediction yet
            objective, losses, success, first = self._frame_loss(frame, previous_motion)
            self.optimizer.zero_grad()
            objective.backward()
            norm = torch.nn.utils.clip_grad_norm_(
                self.net.parameters(), self.config.max_grad_norm if self.config.max_grad_norm else float("inf")
            )
            window_norm.append(float(norm))
            self.optimizer.step()
            if first.ok:  # like the environment: a failed frame keeps the last good motion
                previous_motion = (first.rotation, first.translation)
            window_loss.extend(losses)
            window_success.extend(success)
            self.step += 1
            bar.update()
            if self.step % self.config.eval_every == 0 or i == frames - 1:
                entry = TrainingLog(
                    self.step, float(np.mean(window_loss)), float(np.mean(window_success)), grad_norm=float(np.median(window_norm))
                )
                entry.eval_success = self.evaluate(self.config.eval_frames)
                self.history.append(entry)
                if entry.eval_success >= self.best_eval:
                    # Policy-gradient estimates are noisy: keep the weights that evaluated best.
                    self.best_eval = entry.eval_success
                    self.best_state = copy.deepcopy(self.net.state_dict())
                bar.set_postfix(loss=f"{entry.mean_loss:.3f}", train_succ=f"{entry.success_rate:.2f}", eval_succ=f"{entry.eval_success:.2f}")
                if self.on_log:
                    self.on_log(entry)
                window_loss, window_success, window_norm = [], [], []
                self.net.train()
        bar.close()
        if self.config.keep_best and self.best_state is not None:
            self.net.load_state_dict(self.best_state)
        return self.net

    @torch.no_grad()
    def evaluate(self, n_frames: int, epsilon: float | None = None, seed: int = 10_000) -> float:
        """Success rate at ``eval_epsilon`` (held-out seeds), one pool of ``budget`` hypotheses per frame."""
        self.net.eval()
        epsilon = self.config.eval_epsilon if epsilon is None else epsilon
        stream = frame_stream(self.config.simulation(epsilon), seed)
        rng = np.random.default_rng(seed)
        previous_motion, ok = None, []
        for _ in range(n_frames):
            frame = next(stream)
            if frame.index == 1:
                previous_motion = None
            feats = compute_features(frame.prev, frame.curr, frame.scores, frame.camera, frame.noise_sigma, previous_motion)
            logits = self.net(torch.from_numpy(feats)[None], torch.ones(1, frame.n, dtype=torch.bool))[0]
            p = torch.softmax(logits.double(), 0).numpy()
            problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
            samples = WeightedSampler(p).draw(self.config.budget, rng)
            est = run_pool(problem, samples, self.config.method, self.options, rng)
            ok.append(pose_loss(est, frame) < 1.0)
            if est.ok:
                previous_motion = (est.rotation, est.translation)
        return float(np.mean(ok))

    def save(self, path: str | Path) -> Path:
        state = {"step": self.step, "optimizer": self.optimizer.state_dict(), "history": [dataclasses.asdict(h) for h in self.history]}
        return save_checkpoint(path, self.net, {"algo": "ngransac", **dataclasses.asdict(self.config)}, state)

    @classmethod
    def resume(cls, path: str | Path, **overrides) -> "NGRansacTrainer":
        """The trainer of the checkpoint ``path`` (network, optimiser state, step count, history), to
        continue training with :meth:`train`; ``overrides`` change the fields of
        :data:`RESUMABLE_FIELDS` only (``frames``: the new total).

        Raises:
            ValueError: an override of another field (the checkpoint fixes it), naming it and the value;
                an unusable checkpoint (:class:`~agents.checkpoint.CheckpointError`, naming the file).
        """
        fixed = [f"{k}={value_repr(v)}" for k, v in overrides.items() if k not in RESUMABLE_FIELDS]
        if fixed:
            raise ValueError(f"NGRansacTrainer.resume: the checkpoint {path} fixes {', '.join(fixed)}; a resumed run"
                             f" changes only {', '.join(RESUMABLE_FIELDS)}")
        net, payload = load_checkpoint(path)
        cfg = {k: v for k, v in payload["config"].items() if k != "algo"}
        cfg.update(overrides)
        for key in ("epsilon_range", "outlier_mix"):
            cfg[key] = tuple(cfg[key])
        trainer = cls(NGRansacConfig(**cfg), net=net)
        state = payload.get("trainer_state", {})
        if "optimizer" in state:
            trainer.optimizer.load_state_dict(state["optimizer"])
        trainer.step = int(state.get("step", 0))
        trainer.history = [TrainingLog(**h) for h in state.get("history", [])]
        trainer.rng = np.random.default_rng([trainer.config.seed, trainer.step])
        return trainer
