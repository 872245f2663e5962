"""``vo-gym evaluate``: agents side by side with classical methods on the same held-out frames.

``--agent`` (repeatable) takes a heuristic (uniform, match-score, consistency,
constant-velocity), ``oracle`` (reads the labels: an upper bound, labelled as
such), a shipped learned sampler by name (one-shot or in-frame: :mod:`agents.catalog`)
or a checkpoint of either kind (``.pt`` from ``vo-gym train``, or a PPO ``.zip``).
``--outlier-preset hostile`` runs the sweeps on match errors no shipped sampler was
trained on.
The protocol is :mod:`agents.evaluation`'s: every agent and every classical
method of a setting sees the identical frames (the environment seeded with
``--seed + episode``), (a) over contamination at ``--budget`` hypotheses and
(b) over ``--budgets`` at ``--sweep-epsilon``.

Writes to ``--out`` (default ``runs/evaluate``): ``frames.csv`` (one row per
frame and method), ``summary.json``, ``summary.md`` (the tables printed here)
and ``success_vs_epsilon.png``, ``success_vs_budget.png``. ``--json`` prints
the summary as JSON on stdout instead of the tables.

Every finished unit (an agent's episode, or the classical methods on one episode's frames) is
appended to ``journal.csv`` at once; an interrupt keeps them and ``--resume`` runs only the
missing units, ending with the files an uninterrupted run writes. ``--backend ray`` runs the
units as Ray tasks (``--address`` for a cluster); the rows never depend on the backend or the
worker count.

An option that the chosen run (the sweeps, ``--adaptive`` or ``--source``) does not read is refused
in one line before anything runs (:data:`READ_BY`), and so is an ``--env-kwargs`` keyword that
contradicts the flag setting it (``--auc``, ``--outlier-preset``, ``--max-iterations``).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from agents.catalog import IN_FRAME_SAMPLERS, ONE_SHOT_SAMPLERS
from vo_gym_cli.commands.baselines import PLOT_FORMATS, add_backend_options, backend_from_args
from vo_gym_cli.commands.arguments import (
    OUTLIER_PRESETS,
    bounded_int,
    csv_list,
    max_correspondences,
    max_count,
    max_frames,
    output_path,
    positive_int,
    seed,
)
from vo_gym_cli.commands.common import (
    RunStart,
    UsageError,
    check_step_env,
    interrupted_run,
    open_run_folder,
    stoppable,
    unread_option,
)

DEFAULT_AGENTS = ("uniform", "match-score", "consistency", "constant-velocity", "oracle")


def add_parser(parser: argparse.ArgumentParser) -> None:
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    parser.epilog = (
        "agents: heuristics uniform, match-score, consistency, constant-velocity (no torch needed);"
        " oracle (upper bound, reads labels);\n"
        f"        shipped learned samplers {', '.join(ONE_SHOT_SAMPLERS)} (one-shot: the env's priors) and"
        f" {', '.join(IN_FRAME_SAMPLERS)} (in-frame: through agents.LearnedEstimator on the same frames, at each"
        " budget batch after batch, and with --adaptive-agents under their own stop) (needs the train extra);"
        " or a checkpoint path of either kind (.pt, PPO .zip)\n"
        f"--adaptive: the in-frame comparison (BANSAC, ARS, ... beside {', '.join(IN_FRAME_SAMPLERS)})\n"
        "classical rows: '<method> (fixed)' at the agents' budget and recipe; '<method> (adaptive)' with its own"
        " stop and the environment's recipe (sample polish + final refinement), as the agents;"
        " '<method> (adaptive, textbook)' with its own stop and the core's defaults\n"
        "default: 10 episodes x 10 frames per setting, 5 contaminations + 7 budgets, N 500 (a few minutes on 2 cores)"
    )
    parser.add_argument("--agent", action="append", default=None, metavar="NAME|CHECKPOINT",
                        help=f"agent to evaluate, repeatable: a heuristic, oracle, a shipped sampler"
                             f" ({', '.join(ONE_SHOT_SAMPLERS + IN_FRAME_SAMPLERS)}) or a checkpoint path of either kind"
                             f" (default: {', '.join(DEFAULT_AGENTS)})")
    parser.add_argument("--env-id", default="vo_gym/StereoVO-v0", help="environment id (default: vo_gym/StereoVO-v0)")
    parser.add_argument("--episodes", type=positive_int("--episodes"), default=10,
                        help="episodes per setting (default: 10)")
    parser.add_argument("--frames-per-episode", type=bounded_int("--frames-per-episode", 1, max_frames), default=10,
                        help="frame pairs per episode (default: 10)")
    parser.add_argument("--seed", type=seed, default=1000,
                        help="seed of the first episode; episode i uses seed+i (default: 1000, away from"
                             " training seeds)")
    parser.add_argument("--budget", type=bounded_int("--budget", 1, max_count), default=16,
                        help="hypotheses per frame of the contamination sweep (default: 16)")
    parser.add_argument("--epsilons", type=csv_list(float, "--epsilons"), default=[0.3, 0.5, 0.7, 0.8, 0.9],
                        metavar="E,...", help="contaminations of sweep (a) (default: 0.3,0.5,0.7,0.8,0.9)")
    parser.add_argument("--budgets", type=csv_list(int, "--budgets"), default=[1, 2, 4, 8, 16, 32, 64],
                        metavar="B,...", help="hypothesis budgets of sweep (b) (default: 1,2,4,8,16,32,64)")
    parser.add_argument("--sweep-epsilon", type=float, default=0.8,
                        help="contamination of the budget sweep (default: 0.8)")
    parser.add_argument("--n", type=bounded_int("--n", 3, max_correspondences), default=500,
                        help="correspondences per frame (default: 500)")
    parser.add_argument("--auc", type=float, default=None,
                        help="match-score ROC AUC (default: the env id's own, 0.75 for StereoVO-v0)")
    parser.add_argument("--methods", type=csv_list(str, "--methods"), default=None, metavar="A,B,...",
                        help="classical methods side by side (default: ransac,msac,prosac,guided;"
                             " 'guided' = ransac with the match scores as sampling priors; 'none' for none)")
    parser.add_argument("--max-iterations", type=bounded_int("--max-iterations", 1, max_count), default=None,
                        help="hypothesis cap of the adaptive classical runs (default: --env-kwargs' max_iterations,"
                             " else 2000)")
    parser.add_argument("--outlier-preset", default=None, choices=list(OUTLIER_PRESETS),
                        help="the environment's match errors (its 'outliers' keyword): default, or hostile"
                             " (independent left/right mismatches, duplicates, far clutter, repetitive texture,"
                             " Student-t pixel noise), which no shipped sampler was trained on (default: the env"
                             " id's own)")
    parser.add_argument("--env-kwargs", default=None, metavar="JSON",
                        help="further environment keyword arguments as a JSON object, e.g. '{\"noise_sigma\": 1.0}'")
    parser.add_argument("--out", type=output_path(), default=Path("runs/evaluate"),
                        help="output folder (default: runs/evaluate)")
    parser.add_argument("--json", action="store_true", help="print the summary as JSON instead of the tables")
    parser.add_argument("--no-plots", action="store_true", help="skip the figures")
    parser.add_argument("--format", choices=PLOT_FORMATS, default="png", dest="plot_format",
                        help="file format of the figures (default: png)")
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    parser.add_argument("--adaptive", action="store_true",
                        help="run the in-frame adaptive comparison instead (agents.evaluation.in_frame): the learned"
                             " in-frame sampler, BANSAC, ARS, one-shot samplers, uniform and PROSAC by score on"
                             " identical held-out frames at eps 0.9 and on the hard id at eps 0.8; uses"
                             " --adaptive-sampler, --episodes, --frames-per-episode, --seed, --n, --out, --overwrite,"
                             " --json, --no-plots (figures are PNG) and --no-progress (its per-row lines); refuses"
                             " the others")
    parser.add_argument("--adaptive-sampler", default=None, metavar="NAME|PATH",
                        help=f"with --adaptive: the learned in-frame sampler, a shipped name"
                             f" ({', '.join(IN_FRAME_SAMPLERS)}) or a checkpoint file (default: adaptive-pg-prior)")
    parser.add_argument("--adaptive-agents", action="store_true",
                        help="also run each agent without a budget: its priors with the prior-aware adaptive stop"
                             " (capped at --max-iterations), reported beside the adaptive classical methods"
                             " (PROSAC's own stop among them)")
    parser.add_argument("--source", default=None, metavar="rendered[:PRESET]",
                        help="evaluate on rendered images (vo_gym/StereoVOImages-v0, the image front end) instead of"
                             " simulated matches: each episode rendered once and replayed to every agent at every"
                             " --budgets value; uses --agent, --methods, --episodes, --frames-per-episode, --seed,"
                             " --budgets, --resolution, --out, --overwrite (no --resume: it keeps no journal)"
                             " (needs the images and render extras; default: simulated matches)")
    parser.add_argument("--resolution", default=None, choices=["kitti", "vga"],
                        help="with --source: the rendered image size, kitti (1241x376) or vga (640x480)"
                             " (default: kitti)")
    add_backend_options(parser, "episodes")


def run(args: argparse.Namespace) -> int:
    return stoppable("evaluate", lambda: _run(args))


# EvalConfig's field -> the flag that sets it.
_CONFIG_FLAGS = {
    "env_id": "--env-id", "episodes": "--episodes", "frames_per_episode": "--frames-per-episode", "seed": "--seed",
    "budget": "--budget", "epsilons": "--epsilons", "budgets": "--budgets", "sweep_epsilon": "--sweep-epsilon",
    "n": "--n", "score_auc": "--auc", "max_iterations": "--max-iterations", "methods": "--methods",
    "env_kwargs": "--env-kwargs",
}


def _config_error(err: ValueError) -> UsageError:
    """EvalConfig's refusal, or the environments' (:func:`agents.evaluation.run.check_environments`), as a
    usage error: a field's (:class:`~vo_gym.settings.FieldError`, which names it) says the same of the
    flag that set it; any other keeps its own words."""
    from vo_gym.settings import FieldError

    if isinstance(err, FieldError) and err.field in _CONFIG_FLAGS:
        return UsageError(err.named(_CONFIG_FLAGS[err.field]))
    return UsageError(str(err))


SWEEPS, ADAPTIVE, IMAGES = "sweeps", "adaptive", "images"
# The options each of evaluate's three runs reads (argparse dests); --episodes, --frames-per-episode,
# --seed, --out, --overwrite, --json, --no-plots and --no-progress serve all three. An option typed
# on the command line (even at its default value) that the chosen run does not read is refused rather
# than silently ignored: --adaptive --methods msac would otherwise report rows of methods never asked for.
READ_BY = {
    SWEEPS: frozenset({"agent", "env_id", "budget", "epsilons", "budgets", "sweep_epsilon", "n", "auc", "methods",
                       "max_iterations", "outlier_preset", "env_kwargs", "plot_format", "adaptive_agents", "backend",
                       "workers", "address", "resume"}),
    ADAPTIVE: frozenset({"adaptive_sampler", "n"}),
    IMAGES: frozenset({"source", "resolution", "agent", "methods", "budgets", "plot_format"}),
}
_RUN_NAMES = {SWEEPS: "the sweeps on simulated matches", ADAPTIVE: "--adaptive", IMAGES: "--source rendered"}


def _why_not(run: str, dest: str) -> str:
    """Why ``run`` does without the option ``dest``, where naming the run does not say it."""
    if dest == "resume":
        return "it keeps no journal to resume from; --overwrite replaces the run"
    if dest in ("backend", "workers", "address"):
        return "it runs in this process"
    if run == ADAPTIVE and dest == "agent":
        return "its learned sampler is --adaptive-sampler, its other rows are fixed"
    if run == ADAPTIVE and dest == "plot_format":
        return "its figures are PNG"
    if run == ADAPTIVE:
        return "its samplers and settings are fixed: eps 0.9, and the hard id at eps 0.8"
    if run == IMAGES and dest in ("env_id", "epsilons", "sweep_epsilon", "n", "auc", "outlier_preset", "env_kwargs"):
        return "the matches and their contamination are the image front end's"
    return ""


def check_options_apply(args: argparse.Namespace) -> None:
    """Raise a one-line UsageError naming the first given option that the chosen run (the sweeps,
    ``--adaptive`` or ``--source``) does not read, its value, the run(s) that read it and why not here."""
    run = ADAPTIVE if args.adaptive else IMAGES if args.source is not None else SWEEPS
    unread = unread_option(args, add_parser, READ_BY, run)
    if unread is None:
        return
    given, dest, owners = unread
    if run == ADAPTIVE and dest == "source":  # the option selects a run of its own
        raise UsageError(f"--adaptive and {given} exclude each other: --adaptive compares in-frame samplers on "
                         "simulated frames, --source runs on images; give one")
    here = {SWEEPS: "to the sweeps on simulated matches", ADAPTIVE: "with --adaptive",
            IMAGES: f"with --source {args.source}"}[run]
    why = _why_not(run, dest)
    raise UsageError(f"{given} applies to {' and '.join(_RUN_NAMES[r] for r in owners)}, not {here}"
                     + (f" ({why})" if why else ""))


def _check_step_env(env_id: str) -> None:
    """Refuse an in-frame or image id, which the sweeps cannot step, before any header or folder
    (an unknown id passes: check_environments names it, with the registered ones)."""
    check_step_env(env_id, in_frame_hint="the sweeps step a one-shot id such as vo_gym/StereoVO-v0, and in-frame"
                   " samplers are compared with --adaptive",
                   images_hint="evaluate on rendered images with --source rendered")


# An environment keyword that one of evaluate's own options sets -> that option; the other keywords
# that the options set (n_frames, n_correspondences, outlier_ratio, budget) EvalConfig refuses outright.
_FLAG_KEYWORDS = {"outliers": ("--outlier-preset", "outlier_preset"), "score_auc": ("--auc", "auc"),
                  "max_iterations": ("--max-iterations", "max_iterations")}


def _environment_keywords(args: argparse.Namespace) -> dict:
    """``--env-kwargs`` with the keywords the flags set: a keyword that contradicts its flag is refused,
    so that the frames and the report's header agree on one value."""
    env_kwargs = {}
    if args.env_kwargs:
        try:
            env_kwargs = json.loads(args.env_kwargs)
        except json.JSONDecodeError as err:
            raise UsageError(f"--env-kwargs is not valid JSON: {err}") from None
        if not isinstance(env_kwargs, dict):
            raise UsageError("--env-kwargs must be a JSON object") from None
    for key, (flag, dest) in _FLAG_KEYWORDS.items():
        value = getattr(args, dest)
        if value is not None and key in env_kwargs and env_kwargs[key] != value:
            raise UsageError(f"{flag} {value} contradicts --env-kwargs' {key}={env_kwargs[key]!r}; set it with "
                             f"{flag} alone")
    if args.outlier_preset is not None:
        env_kwargs["outliers"] = args.outlier_preset
    return env_kwargs


def _classical_methods(args: argparse.Namespace, default: tuple[str, ...]) -> tuple[str, ...]:
    """``--methods``, where 'none' (any case) stands for no classical method."""
    return default if args.methods is None else tuple(m for m in args.methods if m.lower() != "none")


def _run_adaptive(args: argparse.Namespace) -> int:
    from agents.adaptive.checkpoint import load_adaptive
    from agents.evaluation.in_frame import AdaptiveComparison, comparison_markdown, run_comparison, write_comparison

    sampler = args.adaptive_sampler or "adaptive-pg-prior"
    try:
        load_adaptive(sampler)  # a bad checkpoint is named before any computing
    except (ValueError, FileNotFoundError, KeyError) as err:
        raise UsageError(f"--adaptive-sampler {sampler!r}: {err}") from None
    config = AdaptiveComparison(learned=sampler, episodes=args.episodes,
                                frames_per_episode=args.frames_per_episode, seed=args.seed, n=args.n)
    out = open_run_folder(args, resumable=False)  # before any computing
    # its per-row lines are its progress
    result = run_comparison(config, log=(lambda line: None) if args.json or args.no_progress else print)
    paths = write_comparison(result, out, plots=not args.no_plots)
    if args.json:
        print(json.dumps(result, indent=2, default=float))
        return 0
    print(comparison_markdown(result))
    print(f"wrote {out}/: {', '.join(p.name for p in paths)}")
    return 0


def _run(args: argparse.Namespace) -> int:
    check_options_apply(args)
    # the environment's own cap, named here rather than as the environment's refusal of --env-id's keywords
    over = next((b for b in args.budgets if b > max_count()), None)
    if over is not None:
        from stereovo.options import value_repr

        raise UsageError(f"--budgets must each be <= {max_count()}, got {value_repr(over)}")
    if args.adaptive:
        return _run_adaptive(args)
    if args.source is not None:
        from agents.evaluation.setup import DEFAULT_METHODS
        from vo_gym_cli.commands.evaluate_images import run_on_images

        return run_on_images(args, DEFAULT_AGENTS, _classical_methods(args, DEFAULT_METHODS))
    from agents.evaluation.run import check_environments
    from agents.evaluation.setup import DEFAULT_METHODS, ROW_COLUMNS, EvalConfig, parse_row_value, resolve_agents
    from stereovo.trials import TrialJournal

    _check_step_env(args.env_id)
    env_kwargs = _environment_keywords(args)
    methods = _classical_methods(args, DEFAULT_METHODS)
    try:
        agents = resolve_agents(args.agent or DEFAULT_AGENTS)
    except (ValueError, FileNotFoundError) as err:
        raise UsageError(f"--agent: {err}") from None
    try:
        config = EvalConfig(
            env_id=args.env_id, episodes=args.episodes, frames_per_episode=args.frames_per_episode, seed=args.seed,
            budget=args.budget, epsilons=tuple(args.epsilons), budgets=tuple(args.budgets),
            sweep_epsilon=args.sweep_epsilon, n=args.n, score_auc=args.auc, methods=methods,
            max_iterations=(args.max_iterations if args.max_iterations is not None
                            else env_kwargs.get("max_iterations", EvalConfig.max_iterations)),
            env_kwargs=env_kwargs, adaptive_agents=args.adaptive_agents,
        )
    except ValueError as err:
        raise _config_error(err) from None
    try:
        check_environments(config)  # the id and every keyword, before anything is written
    except ValueError as err:  # a FieldError naming the field whose keyword the environment refused
        raise _config_error(err) from None
    if args.address is not None and args.backend != "ray":
        raise UsageError(f"--address {args.address!r} needs --backend ray")
    start = RunStart(args.out)
    out = open_run_folder(args)  # before any computing
    journal = TrialJournal(out, ROW_COLUMNS, parse_row_value)
    try:
        return _evaluate(args, config, agents, out, journal)
    except (UsageError, ValueError, TypeError, ModuleNotFoundError):
        journal.close()
        if not args.resume and not journal.read():  # nothing finished: leave --out as it was
            start.undo()
        raise


def _evaluate(args, config, agents, out, journal) -> int:
    from dataclasses import asdict

    from agents.evaluation.report import evaluation_markdown, summarize_evaluation, write_evaluation
    from agents.evaluation.run import evaluation_units, run_evaluation
    from agents.evaluation.setup import EvaluationResult
    from stereovo.benchmark import default_workers
    from stereovo.trials import RunInterrupted
    from stereovo.trials.store import RunFolderError

    workers = args.workers or default_workers()
    if any(a.kind == "checkpoint" for a in agents):
        import torch

        # Worker processes run torch on one thread; so does this one, so --workers changes no number
        # (and OpenMP threads contend badly on small shared machines).
        torch.set_num_threads(1)
    units = evaluation_units(config, agents)
    manifest = {"command": "evaluate", "config": config.as_dict(), "agents": [asdict(a) for a in agents]}
    try:
        done = journal.open(manifest, resume=args.resume, keys=range(len(units)))
    except RunFolderError as err:
        raise UsageError(str(err)) from None
    try:
        backend = backend_from_args(args, workers)
        if not args.json:
            print(f"vo-gym evaluate: {len(agents)} agent(s) ({', '.join(a.label for a in agents)}) and"
                  f" {len(config.methods)} classical method(s) on {config.env_id}; {len(config.settings())} settings x"
                  f" {config.episodes} episodes x {config.frames_per_episode} frames; seed {config.seed};"
                  f" {backend.describe()}", flush=True)
            if done:
                print(f"  resuming: {len(done)} of {len(units)} units already in {out}/journal.csv", flush=True)
        try:
            result = run_evaluation(config, agents, workers=workers, progress=not args.no_progress, backend=backend,
                                    journal=journal, done=done)
        finally:
            backend.close()
    except (RunInterrupted, KeyboardInterrupt) as stop:
        return interrupted_run(journal, stop, len(units), out)
    except (ValueError, TypeError) as err:
        raise UsageError(str(err)) from None
    journal.close()
    # The final files come from the journal, so a resumed run writes exactly what an uninterrupted one does.
    stored = journal.read()
    rows = [row for i in range(len(units)) for row in stored[i]]
    result = EvaluationResult(config, list(agents), rows,
                              summarize_evaluation(rows, config, [a.label for a in agents]), result.wall_s)
    paths = write_evaluation(result, out, plots=not args.no_plots, plot_format=args.plot_format)
    if args.json:
        print(json.dumps(json.loads((out / "summary.json").read_text()), indent=2))
        return 0
    print()
    print(evaluation_markdown(result.summary, result.wall_s))
    print(f"wrote {out}/: {', '.join(p.name for p in paths)}")
    return 0
