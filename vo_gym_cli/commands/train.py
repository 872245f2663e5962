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

A resumed ngransac or ppo run goes on with its checkpoint's settings: it takes only the options of
the fields that trainer lets a continuation change (:data:`agents.ngransac.RESUMABLE_FIELDS`,
:data:`agents.ppo.config.RESUMABLE_FIELDS`: how long to train, the continuation's seed, the periods
and the workers); another of its options, typed, is refused in one line naming it
(:func:`check_resume_options`). An option left out keeps the checkpoint's value, and without
``--resume`` the trainer config's default, which ``--help`` reads from the config classes.

A non-empty ``--out`` is refused unless ``--overwrite`` (which first removes the TensorBoard event
files and PPO's periodic zips of the run there, so that its curves and checkpoints do not mix with
the new run's), or unless ``--resume`` names a checkpoint inside it for ngransac or ppo, which
continue that run there (their step count and history go on).

The module runs to about 600 lines because the three trainers share one parser: an option is
declared once, with the table of the config field it sets, so its help, its refusal for another
trainer and its resume rule come from that one place.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path
from typing import Any, Callable

from vo_gym_cli.commands.arguments import (
    bounded_int,
    finite_float,
    max_learning_rate,
    output_path,
    positive_int,
    seed,
)
from vo_gym_cli.commands.common import (
    RunStart,
    UsageError,
    check_output_dir,
    check_step_env,
    given_options,
    late_help,
    require_extras,
    shown_value,
)

# Each trainer's options: argparse dest -> the field of its config that the option sets
# (agents.ngransac.NGRansacConfig, agents.ppo.config.PPOConfig, agents.adaptive.train.AdaptiveTrainConfig).
# An option left out (None) keeps the config's default (or, resumed, the checkpoint's value).
_NGRANSAC_OPTIONS = {
    "seed": "seed", "loss": "loss", "epsilon": "epsilon_range", "frames": "frames", "budget": "budget",
    "pools": "pools", "lr": "learning_rate", "max_grad_norm": "max_grad_norm", "entropy_weight": "entropy_weight",
    "frames_per_sequence": "frames_per_sequence", "eval_every": "eval_every", "eval_frames": "eval_frames",
}
_PPO_OPTIONS = {
    "env_id": "env_id", "n_envs": "n_envs", "seed": "seed", "timesteps": "timesteps", "budget": "budget",
    "eval_frames": "eval_frames", "eval_every": "eval_every", "vec_env": "vec_env",
    "frames_per_episode": "n_frames", "n_correspondences": "n_correspondences", "reward_mode": "reward_mode",
    "n_steps": "n_steps", "batch_size": "batch_size", "n_epochs": "n_epochs", "ppo_lr": "learning_rate",
    "gamma": "gamma", "gae_lambda": "gae_lambda", "clip_range": "clip_range", "ent_coef": "ent_coef",
    "target_kl": "target_kl", "eval_n": "eval_n_correspondences", "width": "width", "blocks": "blocks",
    "log_std_init": "log_std_init", "share_trunk": "share_trunk", "checkpoint_every": "checkpoint_every",
    "epsilon": "epsilon_range", "max_minutes": "max_wall_s",
}
_ADAPTIVE_OPTIONS = {
    "seed": "seed", "resume": "init", "minutes": "minutes", "clock": "clock", "prior": "prior",
    "domain_randomisation": "domain_randomisation", "max_episodes": "max_episodes",
    "frames_per_episode": "frames_per_episode", "n_correspondences": "n",
}
OPTIONS: dict[str, dict[str, str]] = {"ngransac": _NGRANSAC_OPTIONS, "ppo": _PPO_OPTIONS, "adaptive": _ADAPTIVE_OPTIONS}
"""Each trainer's options (argparse dests) -> the config fields they set."""
_SHARED = frozenset({"seed", "resume"})  # options every trainer reads (with --algo, --out, --overwrite, --no-progress)
# how an option's value becomes its field's where the two differ
_CONVERT: dict[str, Callable[[Any], Any]] = {
    "epsilon": lambda text: _epsilon_range(text),
    "max_minutes": lambda minutes: 60.0 * minutes,
    "max_grad_norm": lambda norm: norm or None,  # 0 switches clipping off
}


def _config_class(algo: str) -> type:
    if algo == "ngransac":
        from agents.ngransac import NGRansacConfig

        return NGRansacConfig
    if algo == "ppo":
        from agents.ppo.config import PPOConfig

        return PPOConfig
    from agents.adaptive.train import AdaptiveTrainConfig

    return AdaptiveTrainConfig


def _shown_default(value: Any) -> str:
    if isinstance(value, tuple):
        return ":".join(f"{v:g}" for v in value)
    return f"{value:g}" if isinstance(value, float) else str(value)


def _config_default(dest: str) -> str:
    """``default 11``, or ``default: ngransac 11, ppo 16`` where the trainers that read ``dest`` differ:
    each trainer config class's default of the field the option sets (made when ``--help`` is formatted:
    :func:`~vo_gym_cli.commands.common.late_help`)."""
    shown = []
    for algo, options in OPTIONS.items():
        if dest in options:
            try:
                config = _config_class(algo)
            except ImportError:  # without the 'train' extra the configs cannot be read
                return "default: the trainer config's"
            field = {f.name: f for f in dataclasses.fields(config)}[options[dest]]
            shown.append((algo, _shown_default(field.default)))
    if len({value for _, value in shown}) == 1:
        return f"default {shown[0][1]}"
    return "default: " + ", ".join(f"{algo} {value}" for algo, value in shown)


def _resumable_text() -> str:
    try:
        runs = "; ".join(f"{algo}: {', '.join(_flag(d) for d in OPTIONS[algo] if d in resumable_options(algo))}"
                         for algo in ("ngransac", "ppo"))
    except ImportError:  # without the 'train' extra
        runs = "the options of how long to train, the seed, the periods and the workers"
    return (f"a resumed ngransac or ppo run keeps its checkpoint's settings and takes only ({runs}; --frames and "
            "--timesteps: the new total); adaptive starts fresh training from the weights, with any of its options")


def _flag(dest: str) -> str:
    return "--" + dest.replace("_", "-")


def _config_option(group, *flags: str, **kwargs: Any) -> argparse.Action:
    """An option whose help shows each trainer config's default (``{config_default}`` in its help)."""
    action = group.add_argument(*flags, default=None, **kwargs)
    return late_help(action, config_default=lambda: _config_default(action.dest))


def add_parser(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--algo", choices=("ngransac", "ppo", "adaptive"), default="ngransac",
                        help="trainer: NG-RANSAC-style policy gradient, stable-baselines3 PPO, or the in-frame "
                             "sampler (adaptive: acts inside each frame's RANSAC loop and stops it)")
    parser.add_argument("--out", type=output_path("--out", str), default="runs/train",
                        help="output folder: the checkpoint and training.json; ngransac and ppo also write TensorBoard"
                             " logs under tb/, adaptive its log windows in training.jsonl (default: runs/train)")
    parser.add_argument("--overwrite", action="store_true",
                        help="replace the run in a non-empty --out (its TensorBoard event files and PPO's periodic"
                             " zips are removed first; a --resume checkpoint inside --out continues that run without"
                             " this flag, for ngransac and ppo)")
    parser.add_argument("--seed", type=seed, default=0,
                        help="seed of the simulation, the sampler and the network (default 0; a resumed ngransac or ppo "
                             "run: its checkpoint's)")
    resume = parser.add_argument("--resume", default=None, metavar="CHECKPOINT",
                                 help="checkpoint to continue from (.pt for ngransac, the SB3 .zip for ppo, an in-frame "
                                      ".pt for adaptive; default: start afresh); {resumable}")
    late_help(resume, resumable=_resumable_text)
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    ng = parser.add_argument_group("ngransac")
    _config_option(ng, "--loss", choices=("supervised", "self-supervised", "self-supervised-smooth"),
                   help="task loss: pose error against ground truth; minus the inlier fraction (no ground truth); "
                        "or that plus a motion-smoothness penalty (no ground truth) ({config_default})")
    _config_option(ng, "--frames", type=positive_int("--frames"),
                   help="total training frames (policy-gradient steps; {config_default}); with --resume, the new total")
    _config_option(ng, "--epsilon", type=_epsilon_text,
                   help="training contamination, a value or a range lo:hi ({config_default})")
    _config_option(ng, "--budget", type=positive_int("--budget"),
                   help="hypotheses per pool (ngransac) or per frame (ppo) ({config_default})")
    _config_option(ng, "--pools", type=positive_int("--pools"),
                   help="pools per frame; their mean loss is the baseline ({config_default})")
    _config_option(ng, "--lr", type=finite_float("--lr", 0.0, max_learning_rate, low_open=True, high_open=True),
                   help="Adam learning rate, below 0.1 ({config_default})")
    _config_option(ng, "--max-grad-norm", type=finite_float("--max-grad-norm", 0.0),
                   help="clip the policy gradient's norm to this (0: no clipping; {config_default})")
    _config_option(ng, "--entropy-weight", type=finite_float("--entropy-weight", 0.0),
                   help="entropy bonus on the sampling distribution, normalised by log N ({config_default})")
    _config_option(ng, "--frames-per-sequence", type=positive_int("--frames-per-sequence"),
                   help="frames per simulated training sequence; each starts without a constant-velocity "
                        "prediction ({config_default})")
    _config_option(ng, "--eval-every", type=positive_int("--eval-every"),
                   help="between evaluations: training frames (ngransac), environment steps (ppo) ({config_default})")
    _config_option(ng, "--eval-frames", type=positive_int("--eval-frames"),
                   help="frames per evaluation ({config_default})")
    ppo = parser.add_argument_group("ppo")
    # --seed, --budget, --epsilon, --eval-frames and --eval-every apply to PPO too.
    _config_option(ppo, "--timesteps", type=positive_int("--timesteps"),
                   help="PPO environment steps ({config_default}); with --resume, the new total")
    _config_option(ppo, "--env-id", help="registered step environment id to train in ({config_default})")
    _config_option(ppo, "--n-envs", type=positive_int("--n-envs"), help="environments stepped in parallel ({config_default})")
    _config_option(ppo, "--vec-env", choices=("dummy", "subproc"),
                   help="SB3 vectorised env: DummyVecEnv or SubprocVecEnv ({config_default})")
    _config_option(ppo, "--frames-per-episode", type=positive_int("--frames-per-episode"),
                   help="frame pairs per training episode ({config_default})")
    _config_option(ppo, "--ppo-lr", type=finite_float("--ppo-lr", 0.0, max_learning_rate, low_open=True,
                                                      high_open=True),
                   help="PPO learning rate, below 0.1 ({config_default}; --lr is NG-RANSAC's)")
    _config_option(ppo, "--n-correspondences", type=bounded_int("--n-correspondences", 3),
                   help="matches per training frame ({config_default}; the net serves any N)")
    _config_option(ppo, "--eval-n", type=bounded_int("--eval-n", 3), help="matches per evaluation frame ({config_default})")
    _config_option(ppo, "--reward-mode", choices=("supervised", "inliers", "msac"), help="the env's reward ({config_default})")
    _config_option(ppo, "--n-steps", type=positive_int("--n-steps"), help="rollout steps per env and update ({config_default})")
    _config_option(ppo, "--batch-size", type=positive_int("--batch-size"), help="minibatch size ({config_default})")
    _config_option(ppo, "--n-epochs", type=positive_int("--n-epochs"), help="epochs per update ({config_default})")
    _config_option(ppo, "--gamma", type=finite_float("--gamma", 0.0, 1.0),
                   help="discount ({config_default}: a frame's action mostly affects its own reward, the next "
                        "one's only through the constant-velocity feature)")
    _config_option(ppo, "--gae-lambda", type=finite_float("--gae-lambda", 0.0, 1.0), help="GAE lambda ({config_default})")
    _config_option(ppo, "--clip-range", type=finite_float("--clip-range", 0.0, low_open=True),
                   help="PPO clip range ({config_default})")
    _config_option(ppo, "--ent-coef", type=finite_float("--ent-coef", 0.0), help="entropy bonus ({config_default})")
    ppo.add_argument("--target-kl", type=finite_float("--target-kl", 0.0, low_open=True), default=None,
                     help="stop an update's epochs above this KL (default off)")
    _config_option(ppo, "--width", type=positive_int("--width"), help="actor net width ({config_default})")
    _config_option(ppo, "--blocks", type=positive_int("--blocks"), help="actor net residual blocks ({config_default})")
    _config_option(ppo, "--log-std-init", type=finite_float("--log-std-init", -20.0, 20.0),
                   help="initial log-std of the logits ({config_default})")
    ppo.add_argument("--share-trunk", action="store_true", default=None,
                     help="the critic pools the actor net's embeddings (default: its own trunk)")
    ppo.add_argument("--max-minutes", type=finite_float("--max-minutes", 0.0, low_open=True), default=None,
                     help="stop after this much wall time even before --timesteps (default: no limit)")
    _config_option(ppo, "--checkpoint-every", type=positive_int("--checkpoint-every"),
                   help="environment steps between SB3 zips ({config_default})")
    # --seed, --frames-per-episode, --n-correspondences and --resume (an in-frame checkpoint to start
    # from) apply to the in-frame trainer too.
    ad = parser.add_argument_group("adaptive")
    _config_option(ad, "--minutes", type=finite_float("--minutes", 0.0, low_open=True),
                   help="training time budget in minutes, of --clock ({config_default})")
    _config_option(ad, "--clock", choices=("wall", "cpu"),
                   help="what --minutes counts: wall time, or this process' CPU time (the same budget on a busy "
                        "machine) ({config_default})")
    ad.add_argument("--prior", default=None, metavar="NAME|PATH",
                    help="a one-shot sampler whose logits a fresh network adds to its own: a shipped name "
                         "(e.g. ngransac-supervised) or a one-shot .pt file (default: none)")
    ad.add_argument("--domain-randomisation", action="store_true", default=None,
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


def config_values(args: argparse.Namespace, algo: str, only: set[str] | None = None) -> dict[str, Any]:
    """The config fields of ``algo``'s trainer that the options in ``args`` set (the dests of ``only``,
    if given): an option left out (None) sets nothing, so the config keeps its default."""
    values = {}
    for dest, field in OPTIONS[algo].items():
        value = getattr(args, dest, None)
        if value is not None and (only is None or dest in only):
            values[field] = _CONVERT[dest](value) if dest in _CONVERT else value
    return values


def _config_error(err: Exception, args: argparse.Namespace) -> UsageError:
    """A trainer config's refusal as a usage error: a field's (:class:`~vo_gym.settings.FieldError`,
    which names it) names the option that set it (``--pools must ...``, ``--batch-size=...``); a
    resumed run's field that no option set is the checkpoint's, and the message names the checkpoint.
    Any other refusal (a checkpoint's, a field no option sets) keeps its own words."""
    from vo_gym.settings import FieldError

    dests = {field: dest for dest, field in OPTIONS[args.algo].items() if dest != "resume"}
    if not isinstance(err, FieldError) or err.field not in dests:
        return UsageError(str(err))
    dest = dests[err.field]
    typed = given_options(args, add_parser)
    if args.resume is not None and dest not in typed:
        return UsageError(f"--resume {args.resume}: its training config: {err.subject}{err.rule}")
    return UsageError(err.named(typed.get(dest, _flag(dest))))


def _ngransac_trainer(args: argparse.Namespace):
    """The NG-RANSAC trainer the options ask for: a fresh one, or the checkpoint's with the resumable
    options that were typed (checked, before ``--out`` is made)."""
    from agents.ngransac import NGRansacConfig, NGRansacTrainer

    try:
        if args.resume:
            typed = set(given_options(args, add_parser))
            return NGRansacTrainer.resume(args.resume, **config_values(args, "ngransac", only=typed))
        return NGRansacTrainer(NGRansacConfig(**config_values(args, "ngransac")))
    except FileNotFoundError as err:
        raise UsageError(str(err)) from None
    except ValueError as err:  # CheckpointError is a ValueError: one line naming the file
        raise _config_error(err, args) from None
    except (TypeError, KeyError) as err:  # a checkpoint whose config this version's trainer does not take
        raise UsageError(f"--resume {args.resume}: its training config does not fit this version ({err})") from None


def _train_ngransac(args: argparse.Namespace, out: Path, trainer) -> int:
    from torch.utils.tensorboard import SummaryWriter

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


def ppo_config_from_args(args: argparse.Namespace):
    """The :class:`agents.ppo.config.PPOConfig` of ``vo-gym train --algo ppo`` arguments (a fresh run).

    ``--eval-every`` counts environment steps here; an option left out keeps PPOConfig's default
    (``--eval-every``: 2000), and a given value is taken as given (``--eval-every 250`` is 250).
    """
    from agents.ppo.config import PPOConfig

    return PPOConfig(**config_values(args, "ppo"))


def _ppo_config(args: argparse.Namespace):
    """The PPO run's config (checked, before ``--out`` is made): from the options, or resumed, the zip's
    with the resumable options that were typed."""
    if args.resume is None:
        try:
            return ppo_config_from_args(args)
        except ValueError as err:
            raise _config_error(err, args) from None
    from agents.ppo.archive import read_ppo_config

    try:
        saved = read_ppo_config(args.resume)
    except (ValueError, FileNotFoundError) as err:  # CheckpointError: one line naming the file
        raise UsageError(str(err)) from None
    try:
        return dataclasses.replace(saved, **config_values(args, "ppo", only=set(given_options(args, add_parser))))
    except ValueError as err:
        raise _config_error(err, args) from None


def _train_ppo(args: argparse.Namespace, out: Path, config) -> int:
    from agents.ppo.train import train_ppo

    _clear_previous_run(args, out)
    try:
        result = train_ppo(config, out, resume=args.resume, progress=not getattr(args, "no_progress", False))
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


def _adaptive_config(args: argparse.Namespace):
    """The in-frame trainer's config (checked, before ``--out`` is made)."""
    from agents.adaptive.train import AdaptiveTrainConfig

    try:
        return AdaptiveTrainConfig(**config_values(args, "adaptive"))
    except ValueError as err:
        raise _config_error(err, args) from None


def _train_adaptive(args: argparse.Namespace, out: Path, config) -> int:
    from agents.adaptive.train import train_in_frame

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
USED_BY = {algo: frozenset(options) - _SHARED for algo, options in OPTIONS.items()}
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
        refused.append(f"{given[dest]}{shown_value(getattr(args, dest))}" + f" (an option of {owners}"
                       + (f"; here: {hint})" if hint else ")"))
    if refused:
        raise UsageError(f"--algo {args.algo} does not take " + ", ".join(refused))


def resumable_options(algo: str) -> frozenset[str]:
    """The options (argparse dests) a run of ``algo`` resumed with ``--resume`` reads: ngransac's and
    ppo's that set a field their trainer lets a continuation change
    (:data:`agents.ngransac.RESUMABLE_FIELDS`, :data:`agents.ppo.config.RESUMABLE_FIELDS`); all of
    adaptive's, whose --resume starts fresh training from the weights."""
    if algo == "adaptive":
        return frozenset(OPTIONS[algo])
    if algo == "ngransac":
        from agents.ngransac import RESUMABLE_FIELDS
    else:
        from agents.ppo.config import RESUMABLE_FIELDS
    return frozenset(dest for dest, field in OPTIONS[algo].items() if field in RESUMABLE_FIELDS)


def check_resume_options(args: argparse.Namespace) -> None:
    """With ``--resume`` (ngransac, ppo), raise a one-line UsageError naming every typed option of the
    trainer that the checkpoint fixes (the network, budget, loss or reward, environment, learning
    rate, ...): the resumed run would go on with the checkpoint's value, whatever was typed."""
    if args.resume is None or args.algo == "adaptive":
        return
    resumable = resumable_options(args.algo)
    given = given_options(args, add_parser)
    fixed = [f"{flag}{shown_value(getattr(args, dest))}" for dest, flag in given.items()
             if dest in OPTIONS[args.algo] and dest not in resumable]
    if fixed:
        raise UsageError(f"{', '.join(fixed)}: fixed by the checkpoint --resume {args.resume}, whose run goes on "
                         f"with its own settings; a resumed {args.algo} run takes only "
                         f"{', '.join(_flag(d) for d in OPTIONS[args.algo] if d in resumable)} (start a new run to "
                         "change the others)")


def _check_env_id(env_id: str) -> None:
    """Refuse, in one line, an id PPO cannot train on: unregistered, or not a vo_gym step environment."""
    from vo_gym.names import did_you_mean
    from vo_gym.registration import STEP, env_kind, step_ids

    ids = ", ".join(step_ids())
    check_step_env(env_id, in_frame_hint=f"PPO trains on a step id ({ids}); the in-frame sampler trains with "
                   "--algo adaptive", images_hint=f"PPO trains on simulated matches, a step id ({ids})")
    kind = env_kind(env_id)
    if kind != STEP:
        what = "a registered environment" if kind is None else "a vo_gym step environment"
        raise UsageError(f"--env-id {env_id!r} is not {what}{did_you_mean(env_id, step_ids())}; "
                         f"PPO trains on one of: {ids}")


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

            network = check_adaptive_payload(path, read_payload(path))
            _check_resumed_size(args, network)
    except (ValueError, FileNotFoundError) as err:
        raise UsageError(f"--resume: {err}") from None
    want = IN_FRAME if args.algo == "adaptive" else ONE_SHOT
    if kind != want:
        article = {IN_FRAME: "an", ONE_SHOT: "a"}
        raise UsageError(f"--resume {args.resume}: {article.get(kind, 'a')} {kind} checkpoint; --algo {args.algo} "
                         f"continues {article[want]} {want} one")


def _check_resumed_size(args: argparse.Namespace, network: dict[str, Any]) -> None:
    """Refuse an in-frame checkpoint whose network is not the size the in-frame trainer builds (it
    starts from the weights, into a network of its config's width and blocks)."""
    from agents.adaptive.train import AdaptiveTrainConfig

    config = AdaptiveTrainConfig()
    if (network["width"], network["blocks"]) != (config.width, config.blocks):
        raise UsageError(f"--resume {args.resume}: its network has width {network['width']}, blocks "
                         f"{network['blocks']}; the in-frame trainer builds width {config.width}, blocks {config.blocks}")


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


# The largest --seed each trainer takes: torch.manual_seed takes 64 bits; PPO's seed also seeds numpy's
# legacy generator through stable-baselines3, which takes 32 bits.
_SEED_MAX = {"ngransac": 2**64 - 1, "ppo": 2**32 - 1, "adaptive": 2**64 - 1}


def run(args: argparse.Namespace) -> int:
    check_options_apply(args)
    if args.seed > _SEED_MAX[args.algo]:
        from stereovo.options import value_repr

        raise UsageError(f"--seed must be <= {_SEED_MAX[args.algo]} with --algo {args.algo}, "
                         f"got {value_repr(args.seed)}")
    require_extras("torch", *(("tensorboard",) if args.algo != "adaptive" else ()),
                   *(("stable_baselines3",) if args.algo == "ppo" else ()))
    if args.resume is not None and not Path(args.resume).is_file():
        raise UsageError(f"--resume: no checkpoint at {args.resume!r}")
    if args.algo == "ppo" and args.resume is not None and Path(args.resume).suffix == ".pt":
        raise UsageError(f"--resume {args.resume}: PPO resumes from the SB3 model zip (e.g. "
                         f"{Path(args.resume).with_suffix('.zip')}); the .pt file is the exported actor only")
    if args.algo != "ppo" and args.resume is not None and Path(args.resume).suffix == ".zip":
        raise UsageError(f"--resume {args.resume}: a .zip is a stable-baselines3 PPO model; resume it with --algo ppo")
    check_resume_options(args)
    if args.algo == "ppo" and args.env_id is not None:
        _check_env_id(args.env_id)
    _check_checkpoints(args)
    # the trainer or its config, checked before --out is made: a refused setting leaves no folder
    prepared = {"ngransac": _ngransac_trainer, "ppo": _ppo_config, "adaptive": _adaptive_config}[args.algo](args)
    start = RunStart(args.out)
    out = _open_out(args)  # before any computing: a bad --out loses no training
    train = {"ngransac": _train_ngransac, "ppo": _train_ppo, "adaptive": _train_adaptive}[args.algo]
    try:
        return train(args, out, prepared)
    except UsageError:  # refused as training started (a zip whose environment does not build): --out as it was
        start.undo()
        raise
