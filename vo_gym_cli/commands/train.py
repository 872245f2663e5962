"""``vo-gym train``: train a learned sampling policy.

``--algo ngransac`` runs the NG-RANSAC-style policy-gradient trainer
(:mod:`agents.ngransac`); ``--algo ppo`` runs stable-baselines3 PPO on the
environment through the equivariant custom policy (:mod:`agents.ppo`). Both
show a progress bar, log to TensorBoard under ``<out>/tb``, evaluate
periodically and write checkpoints that carry their config and feature layout;
``--resume CHECKPOINT`` continues from one. ``--algo adaptive`` trains the in-frame
sampler (:func:`agents.adaptive.train.train_in_frame`) within a time budget (``--minutes``)
into ``<out>/adaptive.pt``, ``training.jsonl`` and ``training.json``; ``--resume``
starts from an in-frame checkpoint's weights. An option of another trainer than ``--algo``'s is
refused in one line before anything runs (:data:`USED_BY`), never silently ignored.

A non-empty ``--out`` is refused unless ``--overwrite`` (which first removes the TensorBoard event
files and PPO's periodic zips of the run there, so that its curves and checkpoints do not mix with
the new run's), or unless ``--resume`` names a checkpoint inside it for ngransac or ppo, which
continue that run there (their step count and history go on).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from vo_gym_cli.commands.common import (
    UsageError,
    bounded_int,
    check_output_dir,
    finite_float,
    given_options,
    positive_int,
    require_extras,
    seed,
)


def add_parser(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--algo", choices=("ngransac", "ppo", "adaptive"), default="ngransac",
                        help="trainer: NG-RANSAC-style policy gradient, stable-baselines3 PPO, or the in-frame "
                             "sampler (adaptive: acts inside each frame's RANSAC loop and stops it)")
    parser.add_argument("--out", default="runs/train",
                        help="output folder: the checkpoint and training.json; ngransac and ppo also write TensorBoard"
                             " logs under tb/, adaptive its log windows in training.jsonl (default: runs/train)")
    parser.add_argument("--overwrite", action="store_true",
                        help="replace the run in a non-empty --out (its TensorBoard event files and PPO's periodic"
                             " zips are removed first; a --resume checkpoint inside --out continues that run without"
                             " this flag, for ngransac and ppo)")
    parser.add_argument("--seed", type=seed, default=0, help="seed of the simulation, the sampler and the network")
    parser.add_argument("--resume", default=None, metavar="CHECKPOINT",
                        help="checkpoint to continue from (.pt for ngransac, the SB3 .zip for ppo, an in-frame .pt for "
                             "adaptive; default: start afresh)")
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    ng = parser.add_argument_group("ngransac")
    ng.add_argument("--loss", choices=("supervised", "self-supervised", "self-supervised-smooth"), default="supervised",
                    help="task loss: pose error against ground truth; minus the inlier fraction (no ground truth); "
                         "or that plus a motion-smoothness penalty (no ground truth)")
    ng.add_argument("--frames", type=positive_int("--frames"), default=None,
                    help="total training frames (policy-gradient steps; default 16000); with --resume, the new total")
    ng.add_argument("--epsilon", type=_epsilon_text, default="0.3:0.9", help="training contamination, a value or a range lo:hi")
    # Defaults of None take agents.ngransac.NGRansacConfig's.
    ng.add_argument("--budget", type=positive_int("--budget"), default=None, help="hypotheses per pool (default 11)")
    ng.add_argument("--pools", type=positive_int("--pools"), default=None,
                    help="pools per frame; their mean loss is the baseline (default 8)")
    ng.add_argument("--lr", type=finite_float("--lr", 0.0, low_open=True), default=None, help="Adam learning rate (default 1e-4)")
    ng.add_argument("--max-grad-norm", type=finite_float("--max-grad-norm", 0.0), default=None,
                    help="clip the policy gradient's norm to this (default 5; 0: no clipping)")
    ng.add_argument("--entropy-weight", type=finite_float("--entropy-weight", 0.0), default=None,
                    help="entropy bonus on the sampling distribution, normalised by log N (default 0)")
    ng.add_argument("--frames-per-sequence", type=positive_int("--frames-per-sequence"), default=None,
                    help="frames per simulated training sequence; each starts without a constant-velocity "
                         "prediction (default 10)")
    ng.add_argument("--eval-every", type=positive_int("--eval-every"), default=None,
                    help="frames between evaluations (default 1000; for ppo: environment steps, default 2000)")
    ng.add_argument("--eval-frames", type=positive_int("--eval-frames"), default=None, help="frames per evaluation (default 300)")
    ppo = parser.add_argument_group("ppo")
    ppo.add_argument("--timesteps", type=positive_int("--timesteps"), default=20_000, help="PPO environment steps")
    ppo.add_argument("--env-id", default="vo_gym/StereoVO-v0", help="registered environment id to train in")
    ppo.add_argument("--n-envs", type=positive_int("--n-envs"), default=2, help="environments stepped in parallel")
    # PPO-specific settings (None: agents.ppo.config.PPOConfig's default); --seed, --budget, --epsilon,
    # --eval-frames and --eval-every (environment steps here; default 2000) apply to PPO too.
    ppo.add_argument("--vec-env", choices=("dummy", "subproc"), default=None,
                     help="SB3 vectorised env: DummyVecEnv (default) or SubprocVecEnv")
    ppo.add_argument("--frames-per-episode", type=positive_int("--frames-per-episode"), default=None,
                     help="frame pairs per training episode (default 8)")
    ppo.add_argument("--ppo-lr", type=finite_float("--ppo-lr", 0.0, low_open=True), default=None,
                     help="PPO learning rate (default 1e-4; --lr is NG-RANSAC's)")
    ppo.add_argument("--n-correspondences", type=bounded_int("--n-correspondences", 3), default=None,
                     help="matches per training frame (default 100; the net serves any N)")
    ppo.add_argument("--eval-n", type=bounded_int("--eval-n", 3), default=None,
                     help="matches per evaluation frame (default 500)")
    ppo.add_argument("--reward-mode", choices=("supervised", "inliers", "msac"), default=None,
                     help="the env's reward (default supervised)")
    ppo.add_argument("--n-steps", type=positive_int("--n-steps"), default=None, help="rollout steps per env and update (default 256)")
    ppo.add_argument("--batch-size", type=positive_int("--batch-size"), default=None, help="minibatch size (default 128)")
    ppo.add_argument("--n-epochs", type=positive_int("--n-epochs"), default=None, help="epochs per update (default 4)")
    ppo.add_argument("--gamma", type=finite_float("--gamma", 0.0, 1.0), default=None, help="discount (default 0.5: a frame's action mostly "
                     "affects its own reward, the next one's only through the constant-velocity feature)")
    ppo.add_argument("--gae-lambda", type=finite_float("--gae-lambda", 0.0, 1.0), default=None, help="GAE lambda (default 0.9)")
    ppo.add_argument("--clip-range", type=finite_float("--clip-range", 0.0, low_open=True), default=None, help="PPO clip range (default 0.2)")
    ppo.add_argument("--ent-coef", type=finite_float("--ent-coef", 0.0), default=None, help="entropy bonus (default 0)")
    ppo.add_argument("--target-kl", type=finite_float("--target-kl", 0.0, low_open=True), default=None,
                     help="stop an update's epochs above this KL (default off)")
    ppo.add_argument("--width", type=positive_int("--width"), default=None, help="actor net width (default 32)")
    ppo.add_argument("--blocks", type=positive_int("--blocks"), default=None, help="actor net residual blocks (default 3)")
    ppo.add_argument("--log-std-init", type=finite_float("--log-std-init", -20.0, 20.0), default=None, help="initial log-std of the logits (default 1)")
    ppo.add_argument("--share-trunk", action="store_true", default=None,
                     help="the critic pools the actor net's embeddings (default: its own trunk)")
    ppo.add_argument("--max-minutes", type=finite_float("--max-minutes", 0.0, low_open=True), default=None,
                     help="stop after this much wall time even before --timesteps (default: no limit)")
    ppo.add_argument("--checkpoint-every", type=positive_int("--checkpoint-every"), default=None,
                     help="environment steps between SB3 zips (default 5000)")
    # --seed, --frames-per-episode, --n-correspondences and --resume (an in-frame checkpoint to start
    # from) apply to the in-frame trainer too; None keeps agents.adaptive.train.AdaptiveTrainConfig's default.
    ad = parser.add_argument_group("adaptive")
    ad.add_argument("--minutes", type=finite_float("--minutes", 0.0, low_open=True), default=None,
                    help="training time budget in minutes, of --clock (default 25)")
    ad.add_argument("--clock", choices=("wall", "cpu"), default=None,
                    help="what --minutes counts: wall time, or this process' CPU time (the same budget on a busy "
                         "machine) (default wall)")
    ad.add_argument("--prior", default=None, metavar="NAME|PATH",
                    help="a one-shot sampler whose logits a fresh network adds to its own: a shipped name "
                         "(e.g. ngransac-supervised) or a one-shot .pt file (default: none)")
    ad.add_argument("--domain-randomisation", action="store_true",
                    help="each episode draws its own outlier kinds (the hostile ones included), noise tail and "
                         "score AUC (agents.ngransac.randomised_settings)")
    ad.add_argument("--max-episodes", type=positive_int("--max-episodes"), default=None,
                    help="stop after this many episodes even within --minutes (default: the time budget alone)")


def _epsilon_range(text: str) -> tuple[float, float]:
    """``"0.5"`` -> (0.5, 0.5); ``"0.3:0.9"`` -> (0.3, 0.9); each in [0, 1), lo <= hi."""
    try:
        parts = [float(v) for v in text.split(":")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"--epsilon must be a number or lo:hi, got {text!r}") from None
    if len(parts) == 1:
        parts = parts * 2
    if len(parts) != 2 or not all(0.0 <= p < 1.0 for p in parts) or parts[0] > parts[1]:
        raise argparse.ArgumentTypeError(f"--epsilon must be a number or lo:hi in [0, 1) with lo <= hi, got {text!r}")
    return parts[0], parts[1]


def _epsilon_text(text: str) -> str:
    _epsilon_range(text)  # validated at parse time; kept as text for the trainers' configs
    return text


def _train_ngransac(args: argparse.Namespace, out: Path) -> int:
    from torch.utils.tensorboard import SummaryWriter

    from agents.ngransac import NGRansacConfig, NGRansacTrainer

    try:
        if args.resume:
            overrides = {} if args.frames is None else {"frames": args.frames}
            trainer = NGRansacTrainer.resume(args.resume, **overrides)
        else:
            given = dict(
                budget=args.budget, pools=args.pools, frames=args.frames, learning_rate=args.lr,
                entropy_weight=args.entropy_weight, frames_per_sequence=args.frames_per_sequence,
                eval_every=args.eval_every, eval_frames=args.eval_frames,
            )
            given = {k: v for k, v in given.items() if v is not None}
            if args.max_grad_norm is not None:
                given["max_grad_norm"] = args.max_grad_norm or None  # 0 switches clipping off
            config = NGRansacConfig(loss=args.loss, epsilon_range=_epsilon_range(args.epsilon), seed=args.seed, **given)
            trainer = NGRansacTrainer(config)
    except (ValueError, FileNotFoundError) as err:  # CheckpointError is a ValueError: one line naming the file
        raise UsageError(str(err)) from None
    except (TypeError, KeyError) as err:  # a checkpoint whose config this version's trainer does not take
        raise UsageError(f"--resume {args.resume}: its training config does not fit this version ({err})") from None
    _clear_previous_run(args, out)
    writer = SummaryWriter(str(out / "tb"))
    checkpoint = out / f"ngransac-{trainer.config.loss}.pt"

    def log(entry) -> None:
        writer.add_scalar("train/mean_loss", entry.mean_loss, entry.step)
        writer.add_scalar("train/pool_success", entry.success_rate, entry.step)
        if entry.grad_norm is not None:
            writer.add_scalar("train/grad_norm", entry.grad_norm, entry.step)
        if entry.eval_success is not None:
            writer.add_scalar(f"eval/success_eps{trainer.config.eval_epsilon}", entry.eval_success, entry.step)
        trainer.save(checkpoint)  # periodic checkpoint at every evaluation

    trainer.on_log = log
    remaining = max(trainer.config.frames - trainer.step, 0)
    trainer.train(frames=remaining, progress=not args.no_progress)
    trainer.save(checkpoint)
    writer.close()
    summary = {"checkpoint": str(checkpoint), "steps": trainer.step, "history": [vars(h) for h in trainer.history]}
    (out / "training.json").write_text(json.dumps(summary, indent=2))
    last = trainer.history[-1] if trainer.history else None
    print(f"checkpoint: {checkpoint}")
    if last is not None:
        print(f"step {last.step}: mean loss {last.mean_loss:.3f}, success at eps {trainer.config.eval_epsilon} "
              f"with {trainer.config.budget} hypotheses: {last.eval_success:.3f}")
    return 0


# ``vo-gym train`` option -> agents.ppo.config.PPOConfig field; None (not given) keeps PPOConfig's default.
_PPO_OPTIONS = {
    "env_id": "env_id", "n_envs": "n_envs", "seed": "seed", "timesteps": "timesteps", "budget": "budget",
    "eval_frames": "eval_frames", "eval_every": "eval_every", "vec_env": "vec_env",
    "frames_per_episode": "n_frames", "n_correspondences": "n_correspondences", "reward_mode": "reward_mode",
    "n_steps": "n_steps", "batch_size": "batch_size", "n_epochs": "n_epochs", "ppo_lr": "learning_rate",
    "gamma": "gamma", "gae_lambda": "gae_lambda", "clip_range": "clip_range", "ent_coef": "ent_coef",
    "target_kl": "target_kl", "eval_n": "eval_n_correspondences", "width": "width", "blocks": "blocks",
    "log_std_init": "log_std_init", "share_trunk": "share_trunk", "checkpoint_every": "checkpoint_every",
}


def ppo_config_from_args(args: argparse.Namespace):
    """The :class:`agents.ppo.config.PPOConfig` of ``vo-gym train --algo ppo`` arguments.

    ``--eval-every`` counts environment steps here; an option left out keeps PPOConfig's default
    (``--eval-every``: 2000), and a given value is taken as given (``--eval-every 250`` is 250).
    """
    from agents.ppo.config import PPOConfig

    values = {key: getattr(args, arg) for arg, key in _PPO_OPTIONS.items() if getattr(args, arg, None) is not None}
    if getattr(args, "max_minutes", None) is not None:
        values["max_wall_s"] = 60.0 * args.max_minutes
    if getattr(args, "epsilon", None) is not None:
        values["epsilon_range"] = _epsilon_range(args.epsilon)
    return PPOConfig(**values)


def _train_ppo(args: argparse.Namespace, out: Path) -> int:
    from agents.ppo.train import train_ppo

    try:
        config = ppo_config_from_args(args)
        resume = getattr(args, "resume", None)
        if resume is not None and Path(resume).suffix == ".pt":
            raise ValueError(
                f"--resume {resume}: PPO resumes from the SB3 model zip (e.g. {Path(resume).with_suffix('.zip')}); "
                "the .pt file is the exported actor only"
            )
        _clear_previous_run(args, out)
        result = train_ppo(config, out, resume=resume, progress=not getattr(args, "no_progress", False))
    except (ValueError, FileNotFoundError) as err:
        raise UsageError(str(err)) from None
    print(f"model: {result.zip_path}")
    print(f"checkpoint: {result.checkpoint_path}")
    if result.history:
        last = result.history[-1]
        best = max(result.history, key=lambda h: h["success"])
        uniform = "n/a" if result.uniform_success is None else f"{result.uniform_success:.3f}"
        print(f"step {last['timesteps']}: success at eps {result.config.eval_epsilon:g} with {result.config.budget} "
              f"hypotheses {last['success']:.3f} (best {best['success']:.3f} at step {best['timesteps']}; "
              f"uniform {uniform}) in {result.wall_s:.0f} s")
    return 0


def _train_adaptive(args: argparse.Namespace, out: Path) -> int:
    from agents.adaptive.train import AdaptiveTrainConfig, train_in_frame

    given = {"minutes": args.minutes, "clock": args.clock, "prior": args.prior, "max_episodes": args.max_episodes,
             "frames_per_episode": args.frames_per_episode, "n": args.n_correspondences, "init": args.resume,
             "domain_randomisation": args.domain_randomisation or None}
    flags = {"minutes": "--minutes", "clock": "--clock", "prior": "--prior", "max_episodes": "--max-episodes",
             "frames_per_episode": "--frames-per-episode", "n": "--n-correspondences", "init": "--resume"}
    try:
        config = AdaptiveTrainConfig(seed=args.seed, **{k: v for k, v in given.items() if v is not None})
    except ValueError as err:
        field = next((f for f in flags if str(err).startswith(f"{f} ")), None)
        raise UsageError(f"{flags[field]}{str(err)[len(field):]}" if field else str(err)) from None
    clock = "CPU" if config.clock == "cpu" else "wall"
    print(f"vo-gym train: in-frame sampler, {config.minutes:g} min of {clock} time, seed {config.seed}"
          + (f", prior {config.prior}" if config.prior else "") + (f", from {config.init}" if config.init else "")
          + (", domain-randomised episodes" if config.domain_randomisation else ""))
    result = train_in_frame(config, out, progress=not args.no_progress)
    print(f"checkpoint: {result.checkpoint}")
    line = f"{result.episodes} episodes, {result.frames} frames in {result.wall_s:.0f} s wall / {result.cpu_s:.0f} s CPU"
    if result.log:
        last = result.log[-1]
        extra = ", ".join(f"{k} {v:.3f}" if isinstance(v, float) else f"{k} {v}" for k, v in last.items()
                          if k in ("success", "mean_hypotheses", "stopped"))
        line += f"; last window: {extra}" if extra else ""
    print(line)
    return 0


# The options each trainer reads (argparse dests); --algo, --out, --seed, --resume and --no-progress
# serve all three. An option of another trainer is refused rather than silently ignored: a
# researcher who gives --algo adaptive PPO's --max-minutes would otherwise train for 25 minutes.
USED_BY = {
    "ngransac": frozenset({"loss", "frames", "epsilon", "budget", "pools", "lr", "max_grad_norm", "entropy_weight",
                           "frames_per_sequence", "eval_every", "eval_frames"}),
    "ppo": frozenset(set(_PPO_OPTIONS) - {"seed"} | {"max_minutes", "epsilon"}),
    "adaptive": frozenset({"minutes", "clock", "prior", "domain_randomisation", "max_episodes", "frames_per_episode",
                           "n_correspondences"}),
}
# where a refused option has a counterpart in the chosen trainer
_COUNTERPART = {("adaptive", "max_minutes"): "--minutes", ("ppo", "minutes"): "--max-minutes",
                ("ppo", "lr"): "--ppo-lr", ("adaptive", "frames"): "--max-episodes or --minutes"}


def check_options_apply(args: argparse.Namespace) -> None:
    """Raise a one-line UsageError naming every given option (typed on the command line, even at its
    default value: :func:`~vo_gym_cli.commands.common.given_options`) that ``--algo``'s trainer does
    not read, the trainer(s) that do, and a counterpart if there is one."""
    given = given_options(args, add_parser)
    refused = []
    for dest in sorted(set().union(*USED_BY.values()) - USED_BY[args.algo]):
        if dest not in given:
            continue
        owners = " and ".join(algo for algo, used in USED_BY.items() if dest in used)
        hint = _COUNTERPART.get((args.algo, dest))
        refused.append(f"{given[dest]} {getattr(args, dest)}" + f" (an option of {owners}"
                       + (f"; here: {hint})" if hint else ")"))
    if refused:
        raise UsageError(f"--algo {args.algo} does not take " + ", ".join(refused))


def _check_env_id(env_id: str) -> None:
    import gymnasium as gym

    import vo_gym  # noqa: F401  (registers the vo_gym ids)

    try:
        gym.spec(env_id)
    except gym.error.Error as err:
        ids = sorted(k for k in gym.registry if k.startswith("vo_gym/"))
        raise UsageError(f"--env-id {env_id!r} is not a registered environment ({err}); vo_gym's: {', '.join(ids)}") from None


def _check_checkpoints(args: argparse.Namespace) -> None:
    """Read the checkpoints that ``--resume`` and ``--prior`` name (without running code) and check their
    kind, so that a bad one is refused before ``--out`` is created."""
    from agents.catalog import ONE_SHOT_SAMPLERS
    from agents.checkpoint import IN_FRAME, ONE_SHOT, resolve_sampler

    if args.algo == "adaptive" and args.prior is not None:
        if args.resume is not None:
            raise UsageError("--prior starts a fresh network, --resume continues a checkpoint (which keeps its own "
                             "prior): give one of them")
        if args.prior not in ONE_SHOT_SAMPLERS:
            try:
                kind = resolve_sampler(args.prior)[0]
            except (ValueError, FileNotFoundError) as err:
                raise UsageError(f"--prior {args.prior!r} is not a shipped one-shot sampler (shipped: "
                                 f"{', '.join(ONE_SHOT_SAMPLERS)}) nor a usable checkpoint: {err}") from None
            if kind != ONE_SHOT:
                raise UsageError(f"--prior {args.prior!r} is an {kind} sampler; a prior is a one-shot one")
    if args.resume is None or args.algo == "ppo":
        return
    try:
        kind, _, path = resolve_sampler(args.resume)
        if kind == IN_FRAME and path is not None:  # a file: the in-frame format's own checks, whole
            from agents.adaptive.checkpoint import check_adaptive_payload
            from agents.checkpoint import read_payload

            check_adaptive_payload(path, read_payload(path))
    except (ValueError, FileNotFoundError) as err:
        raise UsageError(f"--resume: {err}") from None
    want = IN_FRAME if args.algo == "adaptive" else ONE_SHOT
    if kind != want:
        article = {IN_FRAME: "an", ONE_SHOT: "a"}
        raise UsageError(f"--resume {args.resume}: {article.get(kind, 'a')} {kind} checkpoint; --algo {args.algo} "
                         f"continues {article[want]} {want} one")


def _continues_in_place(args: argparse.Namespace) -> bool:
    """Whether ``--resume`` continues the run in ``--out`` (ngransac and ppo carry their step count and
    history on there; adaptive's --resume only starts fresh training from the weights)."""
    if args.resume is None or args.algo == "adaptive":
        return False
    return Path(args.out).resolve() in Path(args.resume).resolve().parents


def _open_out(args: argparse.Namespace) -> Path:
    """``--out``, refused when it holds a run that this one would overwrite and mix logs with (unless
    ``--overwrite``, or a --resume that continues it), then proved writable; before any training."""
    out = Path(args.out)
    entries = [p for p in out.iterdir() if not p.name.startswith(".write-check-")] if out.is_dir() else []
    if entries and not args.overwrite and not _continues_in_place(args):
        hint = "" if args.algo == "adaptive" else ", or --resume one of its checkpoints to continue that run"
        raise UsageError(f"--out {str(out)!r} is not empty ({len(entries)} entries); pass --overwrite to replace"
                         f" the run there{hint}")
    return check_output_dir(out, "--out")


def _clear_previous_run(args: argparse.Namespace, out: Path) -> None:
    """With ``--overwrite`` (and no --resume continuing the run there), remove the old run's files that
    the new run would mix with its own; called once the new run's settings are known to be valid, so
    a refused command leaves ``--out`` as it was."""
    if not args.overwrite or _continues_in_place(args):
        return
    # Left in place, the old run's events would be drawn as the new run's curves, and a stale
    # ppo_<steps>_steps.zip beyond the new run's last would pass for one of its checkpoints.
    for stale in [*(out / "tb").rglob("events.out.tfevents.*"), *(out / "checkpoints").glob("ppo_*_steps.zip")]:
        stale.unlink()
    for folder in sorted((out / "tb").rglob("*"), reverse=True):  # SB3 numbers a run after the folders there
        if folder.is_dir() and not any(folder.iterdir()):
            folder.rmdir()


def run(args: argparse.Namespace) -> int:
    check_options_apply(args)
    require_extras("torch", *(("tensorboard",) if args.algo != "adaptive" else ()),
                   *(("stable_baselines3",) if args.algo == "ppo" else ()))
    if args.resume is not None and not Path(args.resume).is_file():
        raise UsageError(f"--resume: no checkpoint at {args.resume}")
    if args.algo == "ppo":
        _check_env_id(args.env_id)
    elif args.resume is not None and Path(args.resume).suffix == ".zip":
        raise UsageError(f"--resume {args.resume}: a .zip is a stable-baselines3 PPO model; resume it with --algo ppo")
    _check_checkpoints(args)
    out = _open_out(args)  # before any computing: a bad --out loses no training
    if args.algo == "adaptive":
        return _train_adaptive(args, out)
    if args.algo == "ngransac":
        return _train_ngransac(args, out)
    return _train_ppo(args, out)
