"""The trainer of the learned in-frame sampler (:func:`train_in_frame`, :func:`train_adaptive`).

Policy gradient in the adaptive environment (REINFORCE over the minimal samples the env drew from
the policy's logits, their ordered log-probabilities as in NG-RANSAC, and over the stop decisions,
a Bernoulli of the stop belief; the return is the frame's reward, hypothesis costs included, minus
a running-mean baseline), with two supervised auxiliary losses that the simulator's labels make
available during training only: the logits are trained as inlier log-odds (binary cross-entropy
against the static-inlier labels: a moving object counts as outliers) and the stop belief against
whether the hypothesis the frame would end on is right (inlier precision >= ``right_precision`` and
recall >= ``right_recall`` among its consensus). :func:`main` is ``python -m agents.adaptive``.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from agents.adaptive.checkpoint import NETWORK_SIZES, load_adaptive, save_adaptive
from agents.adaptive.network import LOGIT_BOUND, AdaptiveSamplerNet, make_action, observation_tensors
from agents.network_size import MAX_NETWORK_PARAMETERS, MAX_NETWORK_SIZE
from agents.ngransac import ordered_triplet_log_prob, randomised_settings
from agents.training_limits import LEARNING_RATE, MAX_LEARNING_RATE, MAX_TRAINING_STEPS
from stereovo.estimation.estimator_options import MAX_COUNT
from stereovo.options import Choice, Integer, Number, Option
from stereovo.simulation.config import MAX_CORRESPONDENCES, MAX_FRAMES
from vo_gym.adaptive_env import StereoVOAdaptiveEnv
from vo_gym.registration import HARD_SETTINGS
from vo_gym.settings import ContaminationRange, FieldError, check_fields


_TRAIN_RULES: dict[str, Option] = {
    "minutes": Number(low=0.0, low_open=True),
    "clock": Choice(choices=("wall", "cpu")),
    # counts within the caps of agents.training_limits, the simulator (frames, matches) and the estimator
    # (hypotheses), so that a typo fails here, naming the field
    "max_episodes": Integer(low=1, high=MAX_TRAINING_STEPS, allow_none=True),
    "frames_per_update": Integer(low=1, high=MAX_TRAINING_STEPS),
    "frames_per_episode": Integer(low=1, high=MAX_FRAMES),
    "n": Integer(low=3, high=MAX_CORRESPONDENCES),
    **{name: Integer(low=1, high=MAX_COUNT) for name in ("batch_size", "max_hypotheses")},
    "seed": Integer(low=0),
    "lr": LEARNING_RATE,
    **{name: Number(low=0.0, high=1.0) for name in ("hard_fraction", "right_precision", "right_recall")},
    # a network a checkpoint can hold (agents.checkpoint refuses larger ones at load)
    **{name: Integer(low=1, high=MAX_NETWORK_SIZE) for name in ("width", "blocks")},
    "epsilons": ContaminationRange(),
    "hard_epsilons": ContaminationRange(),
}
"""The declarations :class:`AdaptiveTrainConfig` is checked by (:mod:`stereovo.options`)."""


@dataclass
class AdaptiveTrainConfig:
    """Training settings (every field is recorded in the checkpoint).

    Attributes:
        minutes: the training budget, in minutes of ``clock`` (> 0); the clock starts after numba's
            kernels are compiled or loaded from its cache (:func:`compile_kernels`).
        frames_per_episode: frames per training trajectory (the constant-velocity feature needs a chain).
        epsilons: contamination range of the standard setting's episodes, drawn per episode.
        hard_fraction: share of episodes on the hard settings (contamination ``hard_epsilons``).
        batch_size, max_hypotheses, hypothesis_cost: the environment's.
        n: correspondences per frame (3 to :data:`~stereovo.simulation.config.MAX_CORRESPONDENCES`).
        lr, width, blocks: optimiser step (Adam's learning rate, in ``(0, 0.1)``:
            :data:`~agents.training_limits.MAX_LEARNING_RATE`) and network size.
        pg_weight, inlier_weight, stop_weight: weights of the policy-gradient and the two auxiliary losses.
        right_precision, right_recall: when the hypothesis a frame would end on counts as right.
        frames_per_update: frames whose losses are summed per optimiser step.
        seed: seeds the episodes (``seed + episode``) and torch.
        clock: what ``minutes`` counts: ``"wall"`` (wall clock) or ``"cpu"`` (this process' CPU time,
            the budget that stays the same on a busy machine).
        init: checkpoint whose weights training starts from (``None``: fresh weights); its own
            training time adds to this run's in the budget of the result.
        prior: one-shot sampler (a shipped name or a ``.pt`` path) whose logits a fresh network adds
            to its own (``None``: none; see :class:`~agents.adaptive.network.AdaptiveSamplerNet`); that sampler's training time
            is its own.
        domain_randomisation: each episode draws its own match-error process
            (:func:`agents.ngransac.randomised_settings`: outlier-kind weights over every simulated
            kind, the hostile ones included, a Student-t noise tail on half the episodes, a score
            AUC in [0.55, 0.9]) in place of the standard and hard settings' mixes; the hard /
            standard split then only picks the contamination range.
        max_episodes: stop after this many episodes if the time budget lasts that long (None: the
            budget alone).
    """

    minutes: float = 25.0
    frames_per_episode: int = 8
    epsilons: tuple[float, float] = (0.6, 0.92)
    hard_fraction: float = 0.5
    hard_epsilons: tuple[float, float] = (0.6, 0.85)
    batch_size: int = 4
    max_hypotheses: int = 64
    hypothesis_cost: float = 0.002
    n: int = 500
    lr: float = 1e-3
    width: int = 32
    blocks: int = 2
    pg_weight: float = 0.2
    inlier_weight: float = 1.0
    stop_weight: float = 1.0
    right_precision: float = 0.9
    right_recall: float = 0.3
    frames_per_update: int = 4
    seed: int = 0
    log_every_s: float = 30.0
    clock: str = "wall"
    init: str | None = None
    prior: str | None = None
    max_episodes: int | None = None
    domain_randomisation: bool = False
    extra: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        check_fields(_TRAIN_RULES, vars(self))
        count = AdaptiveSamplerNet.parameter_count(NETWORK_SIZES["n_features"], NETWORK_SIZES["n_globals"],
                                                   self.width, self.blocks)
        if count > MAX_NETWORK_PARAMETERS:
            raise FieldError("width", f" {self.width} and blocks {self.blocks} make a network of {count:,} "
                             f"parameters, more than the {MAX_NETWORK_PARAMETERS:,} a checkpoint may hold")
        if self.prior is not None and self.init is not None:
            raise FieldError("prior", " starts a fresh network; init continues a checkpoint (which keeps its own "
                                      "prior)")


def episode_settings(config: AdaptiveTrainConfig, episode: int) -> tuple[dict[str, Any], bool]:
    """The adaptive environment's simulator keywords for training episode ``episode`` (a function of
    ``config.seed`` and ``episode``), and whether it is a hard-setting episode."""
    rng = np.random.default_rng([config.seed, episode])
    hard = rng.random() < config.hard_fraction
    low, high = config.hard_epsilons if hard else config.epsilons
    kwargs = dict(HARD_SETTINGS) if hard else {}
    if config.domain_randomisation:
        kwargs = randomised_settings(rng)
    kwargs["outlier_ratio"] = float(rng.uniform(low, high))
    return kwargs, hard


def _training_env(config: AdaptiveTrainConfig, episode: int) -> tuple[StereoVOAdaptiveEnv, dict]:
    kwargs, hard = episode_settings(config, episode)
    return _environment(config, kwargs), {"hard": hard, "epsilon": kwargs["outlier_ratio"]}


def _environment(config: AdaptiveTrainConfig, settings: dict[str, Any]) -> StereoVOAdaptiveEnv:
    """The adaptive environment of ``config`` with an episode's simulator keywords ``settings``."""
    return StereoVOAdaptiveEnv(
        batch_size=config.batch_size, max_hypotheses=config.max_hypotheses, hypothesis_cost=config.hypothesis_cost,
        n_frames=config.frames_per_episode, n_correspondences=config.n, **settings,
    )


WARM_UP_ENDS = ("found", "missed", "capped")
"""How :func:`compile_kernels` ends its frames: a motion found (logits on the labelled inliers, a stop after
the first batch), one missed (uniform logits, a stop after the first batch), the hypothesis cap (no stop)."""


def compile_kernels(config: AdaptiveTrainConfig) -> None:
    """Run frames of each kind of episode that ``config`` trains, ended in each way a training frame can end
    (:data:`WARM_UP_ENDS`), so that numba's kernels (the simulator's, the features', the estimator's) are
    compiled or loaded from its cache before a budget is timed.

    The kinds: the first standard and the first hard episode that training would meet (their settings), and
    with ``domain_randomisation`` each of them again with every outlier kind in its mix (a drawn mix may leave
    a kind out). Each way runs on the episode's first two frames, the second with the first's estimate for
    its prediction features. The kernels a frame needs depend on where its search ends and on its random
    draws, not on its settings alone: a warm-up of uniform logits only had left the final refinement and the
    prediction features to compile inside the budget whenever those first frames all missed (measured with
    an empty numba cache: 9 to 13 s of the first episode with ``hard_fraction=0`` or ``domain_randomisation``,
    0.1 s once warmed), and the simulator's redraw of rows that noise sent out of the image whenever none did
    (one more frame, with 10 px of noise, runs it).
    Draws nothing from torch's generator and changes nothing training reads: the same config trains the
    same weights with or without it."""
    from stereovo.simulation import OUTLIER_KINDS, SimulationConfig, simulate_frame

    # the simulator's redraw of rows that noise sent out of the image: always at 10 px of noise
    simulate_frame(SimulationConfig(n_correspondences=200, outlier_ratio=0.5, noise_sigma=10.0), rng=0)
    first: dict[bool, int] = {}
    # hard_fraction 0 or 1 has one kind only, and a rare kind may not come within 64 episodes: its
    # few kernels of its own then compile inside the budget, as before
    for episode in range(64):
        first.setdefault(episode_settings(config, episode)[1], episode)
        if len(first) == 2:
            break
    for episode in first.values():
        settings = episode_settings(config, episode)[0]
        kinds = [settings] + ([{**settings, "outlier_mix": dict.fromkeys(OUTLIER_KINDS, 1.0)}]
                              if config.domain_randomisation else [])
        for kind in kinds:
            env = _environment(config, kind)
            for end in WARM_UP_ENDS:
                _warm_up_frames(env, config.seed * 1_000_003 + episode, end)
            env.close()


def _warm_up_frames(env: StereoVOAdaptiveEnv, seed: int, end: str) -> None:
    """Reset ``env`` with ``seed`` and step its first two frames (or its one), each ended as ``end`` says."""
    obs, _ = env.reset(seed=seed)
    for _ in range(2):
        done = truncated = False
        while not done:
            frame = env.current_frame
            n = frame.n
            logits = np.where(frame.truth.inlier, LOGIT_BOUND, -LOGIT_BOUND) if end == "found" else np.zeros(n)
            step = make_action(logits, obs["mask"][:n], end != "capped" and env.frame_hypotheses > 0)
            action = np.full(env.action_space.shape, -LOGIT_BOUND, dtype=np.float32)
            action[:n], action[-1] = step[:n], step[-1]
            obs, _, _, truncated, info = env.step(action)
            done = info["frame_done"] or truncated
        if truncated:
            return


def right_hypothesis(masks: np.ndarray, weights: np.ndarray, inlier: np.ndarray, precision: float, recall: float) -> bool:
    """Whether the hypothesis selected by ``weights`` among ``masks (H, N)`` is right against the labels."""
    if masks.shape[0] == 0:
        return False
    chosen = masks[int(np.argmax(masks @ weights))]
    found = np.count_nonzero(chosen & inlier)
    return found >= precision * max(np.count_nonzero(chosen), 1) and found >= recall * np.count_nonzero(inlier)


@dataclass
class AdaptiveTrainResult:
    """What :func:`train_in_frame` wrote and how long it took."""

    checkpoint: Path
    log: list[dict[str, Any]]
    episodes: int
    frames: int
    wall_s: float
    cpu_s: float


def train_in_frame(config: AdaptiveTrainConfig, out: str | Path, progress: bool = True) -> AdaptiveTrainResult:
    """Train the in-frame sampler within ``config.minutes`` (of ``config.clock``) into the folder ``out``.

    The library side of ``vo-gym train --algo adaptive``, laid out as the PPO trainer's folder:
    ``out/adaptive.pt`` (the checkpoint, rewritten at every log window, so an interrupted run leaves
    its latest weights), ``out/training.jsonl`` (one line per log window, the last one partial:
    minutes, episodes, frames, success, mean hypotheses, stop share, baseline) and
    ``out/training.json`` (the config and the totals). ``progress`` shows a bar over the time budget.
    The same config run to the same episode count trains the same weights (the stop draws come
    from a generator seeded by ``config.seed``; the caller's torch generator is left as it was).
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    log_path = out / "training.jsonl"
    log_path.write_text("")
    wall, cpu = time.time(), time.process_time()
    checkpoint, totals = _train(config, out / "adaptive.pt", log_path, progress)
    result = AdaptiveTrainResult(checkpoint, totals["log"], totals["episodes"], totals["frames"],
                                 time.time() - wall, time.process_time() - cpu)
    summary = {"algo": "adaptive", "config": asdict(config), "episodes": result.episodes, "frames": result.frames,
               "wall_s": round(result.wall_s, 1), "cpu_s": round(result.cpu_s, 1), "checkpoint": str(checkpoint),
               "log": result.log}
    (out / "training.json").write_text(json.dumps(summary, indent=2) + "\n")
    return result


def train_adaptive(config: AdaptiveTrainConfig, out: str | Path, log_path: str | Path | None = None,
                   progress: bool = False) -> Path:
    """Train :class:`AdaptiveSamplerNet` in the adaptive env for ``config.minutes``; write ``out``."""
    return _train(config, out, log_path, progress)[0]


def _train(config: AdaptiveTrainConfig, out: str | Path, log_path: str | Path | None,
           progress: bool) -> tuple[Path, dict[str, Any]]:
    from tqdm import tqdm

    torch.set_num_threads(1)  # small per-step batches: more threads only contend on a shared machine
    if config.clock not in ("wall", "cpu"):
        raise ValueError(f"clock must be 'wall' or 'cpu', got {config.clock!r}")
    clock = time.time if config.clock == "wall" else time.process_time
    # The network's initialisation draws from torch's global generator (nn.Module has no other way),
    # seeded and then restored so that the caller's stream is untouched; the stop draws come from
    # ``stop_rng``, which continues that seeded stream (the draws of earlier versions, seed for seed).
    with torch.random.fork_rng():
        torch.manual_seed(config.seed)
        if config.init is not None:
            net, payload = load_adaptive(config.init)
            if (net.width, net.blocks) != (config.width, config.blocks):
                raise ValueError(f"init checkpoint {config.init} has width {net.width}, blocks {net.blocks}; "
                                 f"the config asks for {config.width}, {config.blocks}")
            net.train()
        elif config.prior is not None:
            net = AdaptiveSamplerNet.with_prior(config.prior, width=config.width, blocks=config.blocks)
        else:
            net = AdaptiveSamplerNet(width=config.width, blocks=config.blocks)
        stop_rng = torch.Generator()
        stop_rng.set_state(torch.get_rng_state())
    optimiser = torch.optim.Adam(net.parameters(), lr=config.lr)
    bce = nn.BCEWithLogitsLoss()
    # On a first run numba compiles the env's and the estimator's kernels (about half a minute of CPU;
    # stereovo.compilation says so on stderr): that would come out of the budget, and a short budget
    # would then train less or nothing, silently. So they compile first, and the clock starts after.
    compile_kernels(config)
    baseline, log, start, last_log = 0.0, [], clock(), time.time()
    stats = {"frames": 0, "success": 0, "hypotheses": 0, "stops": 0}
    episode, pending = 0, []
    log_file = open(log_path, "a") if log_path else None
    budget_s = 60 * config.minutes
    bar = tqdm(total=round(budget_s), desc=f"in-frame sampler ({config.clock} s)", unit="s", disable=not progress)
    total_frames = 0

    def log_window(window: dict[str, int]) -> None:
        frames = max(window["frames"], 1)
        row = {"minutes": round((clock() - start) / 60, 2), "episodes": episode, "frames": window["frames"],
               "success": round(window["success"] / frames, 3), "mean_hypotheses": round(window["hypotheses"] / frames, 1),
               "stopped": round(window["stops"] / frames, 3), "baseline": round(baseline, 3)}
        log.append(row)
        bar.set_postfix(success=row["success"], hypotheses=row["mean_hypotheses"])
        if log_file:
            log_file.write(json.dumps(row) + "\n")
            log_file.flush()

    while clock() - start < budget_s and (config.max_episodes is None or episode < config.max_episodes):
        bar.n = min(round(clock() - start), bar.total)
        bar.refresh()
        env, setting = _training_env(config, episode)
        obs, info = env.reset(seed=config.seed * 1_000_003 + episode)
        episode += 1
        done = False
        frame_terms: list[torch.Tensor] = []
        frame_aux: list[torch.Tensor] = []
        frame_return = 0.0
        while not done:
            frame = env.current_frame
            inlier = frame.truth.inlier
            features, mask, globals_ = observation_tensors(obs)
            logits, stop_logit = net(features, mask, globals_)
            n = frame.n
            valid_logits = logits[0, :n]
            stop_p = torch.sigmoid(stop_logit[0])
            can_stop = env.frame_hypotheses > 0
            stop = bool(can_stop and torch.rand((), generator=stop_rng) < stop_p.detach())
            weights = torch.softmax(valid_logits.detach(), dim=0).numpy()
            # auxiliary labels: inlier log-odds, and whether stopping now would end on a right hypothesis
            frame_aux.append(config.inlier_weight * bce(valid_logits, torch.as_tensor(inlier, dtype=torch.float32)))
            if can_stop:
                right = right_hypothesis(env.scored_inliers, weights, inlier, config.right_precision, config.right_recall)
                frame_aux.append(config.stop_weight * bce(stop_logit[0], torch.tensor(float(right))))
                frame_terms.append(torch.log(stop_p if stop else 1 - stop_p).clamp_min(-20))
            action = make_action(valid_logits.detach().numpy(), obs["mask"][:n], stop)
            full = np.full(env.action_space.shape, -LOGIT_BOUND, dtype=np.float32)
            full[:n], full[-1] = action[:n], action[-1]
            obs, reward, _, truncated, info = env.step(full)
            frame_return += reward
            if info["batch_count"]:
                log_p = torch.log_softmax(valid_logits.clamp(-LOGIT_BOUND, LOGIT_BOUND), dim=0)
                samples = torch.as_tensor(info["batch_samples"][: info["batch_count"]])
                frame_terms.append(ordered_triplet_log_prob(log_p, samples).sum())
            if info["frame_done"]:
                advantage = frame_return - baseline
                baseline = 0.95 * baseline + 0.05 * frame_return
                pg = -advantage * torch.stack(frame_terms).sum() if frame_terms else torch.zeros(())
                pending.append(config.pg_weight * pg + torch.stack(frame_aux).mean())
                stats["frames"] += 1
                total_frames += 1
                stats["success"] += int(info["success"])
                stats["hypotheses"] += int(info["n_hypotheses"])
                stats["stops"] += int(info["stopped"])
                frame_terms, frame_aux, frame_return = [], [], 0.0
                if len(pending) >= config.frames_per_update:
                    optimiser.zero_grad()
                    torch.stack(pending).mean().backward()
                    nn.utils.clip_grad_norm_(net.parameters(), 5.0)
                    optimiser.step()
                    pending = []
            done = truncated
        if time.time() - last_log >= config.log_every_s:
            last_log = time.time()
            log_window(stats)
            stats = {"frames": 0, "success": 0, "hypotheses": 0, "stops": 0}
            save_adaptive(out, net, asdict(config), log)
    if stats["frames"]:  # the last, partial window: a run shorter than one window still reports
        log_window(stats)
    bar.close()
    if log_file:
        log_file.close()
    return save_adaptive(out, net, asdict(config), log), {"log": log, "episodes": episode, "frames": total_frames}


DEFAULT_OUT = "runs/adaptive-pg.pt"
"""Where ``python -m agents.adaptive`` writes without ``--out``: outside the package, whose shipped
checkpoints (``agents/checkpoints``) only an explicit ``--out`` with ``--overwrite`` replaces."""

# python -m agents.adaptive's options -> the AdaptiveTrainConfig field each sets (a config error names the option)
_MAIN_OPTIONS = {"minutes": "--minutes", "seed": "--seed", "n": "--n", "epsilons": "--epsilons",
                 "hard_epsilons": "--hard-epsilons", "hard_fraction": "--hard-fraction",
                 "right_precision": "--right-precision", "right_recall": "--right-recall", "lr": "--lr",
                 "clock": "--clock", "init": "--init", "prior": "--prior"}


def _shipped_folder() -> Path:
    from importlib import resources

    from agents.catalog import SHIPPED_FOLDER, SHIPPED_PACKAGE

    return Path(str(resources.files(SHIPPED_PACKAGE).joinpath(SHIPPED_FOLDER))).resolve()


def check_out_file(out: str | Path, overwrite: bool) -> str | None:
    """Why ``python -m agents.adaptive`` must not write the checkpoint ``out`` without ``--overwrite``
    (an existing file, or a file in the shipped checkpoints' folder), or None when it may."""
    path = Path(out)
    if path.is_dir():
        return f"--out {str(out)!r} is a directory; give the checkpoint file to write (e.g. {DEFAULT_OUT})"
    if overwrite:
        return None
    if _shipped_folder() == path.resolve().parent:
        return (f"--out {str(out)!r} is in the shipped checkpoints' folder {_shipped_folder()}; pass --overwrite to "
                "write there (scripts/train_adaptive.sh regenerates the shipped samplers)")
    if path.exists():
        return f"--out {str(out)!r} exists; pass --overwrite to replace it"
    return None


def main(argv: list[str] | None = None) -> int:
    """``python -m agents.adaptive --minutes 25 --out runs/adaptive-pg.pt``: train into one checkpoint file.

    A bad option is one line (``python -m agents.adaptive: error: ...``, exit 2) naming it and its value,
    before anything is trained: the config's own checks, the ``--init`` and ``--prior`` checkpoints
    (read without running code), and ``--out`` (:func:`check_out_file`).
    """
    import argparse

    class Parser(argparse.ArgumentParser):
        def error(self, message: str):  # type: ignore[override]
            """One line, ``python -m agents.adaptive: error: MESSAGE``, exit 2 (``--help`` shows the usage)."""
            self.exit(2, f"{self.prog}: error: {' '.join(message.split())}\n")

    defaults = AdaptiveTrainConfig()
    parser = Parser(prog="python -m agents.adaptive",
                    description="train the learned in-frame sampler in the adaptive env")
    parser.add_argument("--minutes", type=float, default=defaults.minutes,
                        help=f"training budget, minutes of --clock (default: {defaults.minutes:g})")
    parser.add_argument("--out", default=DEFAULT_OUT,
                        help="the checkpoint file to write; an existing file, or one in the shipped checkpoints' folder "
                             f"agents/checkpoints, only with --overwrite (default: {DEFAULT_OUT})")
    parser.add_argument("--overwrite", action="store_true",
                        help="replace an existing --out file, or write into agents/checkpoints (regenerating a "
                             "shipped sampler)")
    parser.add_argument("--log", default=None,
                        help="a file to append the log windows to, one JSON line each (default: none)")
    parser.add_argument("--seed", type=int, default=defaults.seed,
                        help=f"seeds the episodes and the network (default: {defaults.seed})")
    parser.add_argument("--n", type=int, default=defaults.n, help=f"correspondences per frame (default: {defaults.n})")
    parser.add_argument("--epsilons", default=None, metavar="LO,HI",
                        help=f"contamination range of the standard episodes (default: {defaults.epsilons})")
    parser.add_argument("--hard-epsilons", default=None, metavar="LO,HI",
                        help=f"contamination range of the hard episodes (default: {defaults.hard_epsilons})")
    parser.add_argument("--hard-fraction", type=float, default=defaults.hard_fraction,
                        help=f"share of hard episodes (default: {defaults.hard_fraction:g})")
    parser.add_argument("--right-precision", type=float, default=defaults.right_precision,
                        help="inlier precision at which a hypothesis counts as right, the stop belief's label "
                             f"(default: {defaults.right_precision:g})")
    parser.add_argument("--right-recall", type=float, default=defaults.right_recall,
                        help="inlier recall at which a hypothesis counts as right, the stop belief's label "
                             f"(default: {defaults.right_recall:g})")
    parser.add_argument("--lr", type=float, default=defaults.lr,
                        help=f"Adam's learning rate, in (0, {MAX_LEARNING_RATE:g}) (default: {defaults.lr:g})")
    parser.add_argument("--clock", choices=("wall", "cpu"), default=defaults.clock,
                        help=f"what --minutes counts: wall clock or this process' CPU time (default: {defaults.clock})")
    parser.add_argument("--init", default=None, metavar="CHECKPOINT",
                        help="start from this in-frame checkpoint's weights, a path or shipped name "
                             "(default: fresh weights)")
    parser.add_argument("--prior", default=None, metavar="SAMPLER",
                        help="a fresh network adds this one-shot sampler's logits to its own "
                             "(a shipped name, e.g. ngransac-supervised, or a one-shot .pt file; default: none)")
    parser.add_argument("--domain-randomisation", action="store_true",
                        help="each episode draws its own outlier kinds, noise tail and score AUC")
    args = parser.parse_args(argv)
    if args.prior is not None and args.init is not None:
        parser.error("--prior starts a fresh network; --init continues a checkpoint (which keeps its own prior)")
    ranges = {}
    for name in ("epsilons", "hard_epsilons"):
        text = getattr(args, name)
        if text is None:
            continue
        try:
            low, high = (float(x) for x in text.split(","))
        except ValueError:
            parser.error(f"--{name.replace('_', '-')} must be LO,HI, got {text!r}")
        if not 0 <= low <= high < 1:
            parser.error(f"--{name.replace('_', '-')} must satisfy 0 <= LO <= HI < 1, got {text!r}")
        ranges[name] = (low, high)
    try:
        config = AdaptiveTrainConfig(minutes=args.minutes, seed=args.seed, n=args.n, hard_fraction=args.hard_fraction,
                                     right_precision=args.right_precision, right_recall=args.right_recall, lr=args.lr,
                                     clock=args.clock, init=args.init, prior=args.prior,
                                     domain_randomisation=args.domain_randomisation, **ranges)
    except ValueError as err:  # a FieldError names the config's field: the message names the option instead
        known = isinstance(err, FieldError) and err.field in _MAIN_OPTIONS
        parser.error(err.named(_MAIN_OPTIONS[err.field]) if known else str(err))
    problem = _check_start(config) or check_out_file(args.out, args.overwrite)
    if problem:
        parser.error(problem)
    train_adaptive(config, args.out, args.log)
    return 0


def _check_start(config: AdaptiveTrainConfig) -> str | None:
    """Why the ``--prior`` or ``--init`` checkpoint of ``config`` cannot start training (read without
    running code: the kind, the whole in-frame file, the network's sizes), or None."""
    from agents.catalog import IN_FRAME, ONE_SHOT
    from agents.checkpoint import SHIPPED_SAMPLERS, read_payload, resolve_sampler

    if config.prior is not None:
        try:
            kind = resolve_sampler(config.prior)[0]
        except (ValueError, FileNotFoundError) as err:
            return f"--prior: {err}"
        if kind != ONE_SHOT:
            return (f"--prior must be a one-shot sampler (shipped: {', '.join(SHIPPED_SAMPLERS)}, or a .pt file), "
                    f"got the {kind} {config.prior!r}")
    if config.init is not None:
        from agents.adaptive.checkpoint import check_adaptive_payload, shipped_adaptive_path

        try:
            kind, name, path = resolve_sampler(config.init)
            if kind != IN_FRAME:
                return f"--init {config.init!r} is a {kind} sampler; training continues an in-frame one"
            path = path if path is not None else shipped_adaptive_path(name)
            network = check_adaptive_payload(path, read_payload(path))
        except (ValueError, FileNotFoundError) as err:
            return f"--init: {err}"
        if (network["width"], network["blocks"]) != (config.width, config.blocks):
            return (f"--init {config.init!r} has width {network['width']}, blocks {network['blocks']}; this trainer "
                    f"builds width {config.width}, blocks {config.blocks}")
    return None
