"""The ``vo-gym`` console script: one subcommand a module under ``vo_gym_cli.commands``.

Each command module exposes ``add_parser(subparsers)`` (declares its options)
and ``run(args) -> int`` (does the work, returns the exit code). Modules are
imported lazily so that ``vo-gym --help`` stays fast and a command's heavy
imports (torch, matplotlib) load only when it runs. Every command runs inside
:func:`vo_gym_cli.commands.common.guarded`: a usage error is one line and exit 2,
Ctrl-C one line and exit 130.

The arguments a command's ``run`` receives also say which options were typed on the command line
(:data:`vo_gym_cli.commands.common.GIVEN_OPTIONS`), which argparse's values alone cannot: an option
typed at its default value looks like one left out.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from vo_gym_cli.commands.common import GIVEN_OPTIONS, ArgumentParser, HelpFormatter, guarded, typed_options

COMMANDS = {
    "vo": "Run stereo visual odometry over a simulated sequence or stereo images and write its trajectory.",
    "baselines": "Compare the classical RANSAC family on a grid of simulated frames.",
    "bench": "Time the estimator (and OpenCV / PoseLib / SupeRANSAC, if installed) on identical frames.",
    "train": "Train a learned sampler (NG-RANSAC-style, PPO, or the in-frame sampler).",
    "evaluate": "Compare learned samplers, heuristics and classical methods on held-out frames.",
    "sweep": "Sweep the NG-RANSAC or PPO trainer's hyperparameters on Ray Tune (a YAML search space).",
}

DESCRIPTION = (
    "vo-gym: a simulated stereo camera, a RANSAC motion estimator with the classical family "
    "(RANSAC, MSAC, PROSAC, MLESAC, LO-RANSAC, USAC, ...), and Gymnasium environments for "
    "learning where to sample."
)
EPILOG = (
    "examples:\n"
    "  vo-gym vo --frames 300 --method probabilistic      visual odometry, writes runs/vo/\n"
    "  vo-gym vo --agent ngransac-supervised              the same with a shipped learned sampler\n"
    "  vo-gym baselines                                   the classical methods side by side\n"
    "  vo-gym evaluate --agent ngransac-supervised        learned vs classical on held-out seeds\n"
    "run 'vo-gym COMMAND --help' for a command's options (each shows its default)."
)


def version() -> str:
    """The installed distribution's version (the source tree's pyproject when not installed)."""
    try:
        from importlib.metadata import PackageNotFoundError, version as dist_version

        return dist_version("vo-gym")
    except PackageNotFoundError:  # running from a source tree that was never installed
        return "unknown (not installed)"


def _command_module(name: str):
    return importlib.import_module(f"vo_gym_cli.commands.{name}")


def build_parser(names: list[str] | None = None) -> argparse.ArgumentParser:
    parser = ArgumentParser(
        prog="vo-gym", description=DESCRIPTION, epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"vo-gym {version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", title="commands", parser_class=ArgumentParser)
    for name in names or COMMANDS:
        try:
            module = _command_module(name)
        except ModuleNotFoundError as err:
            if err.name != f"vo_gym_cli.commands.{name}":
                raise
            continue
        command = sub.add_parser(name, help=COMMANDS[name], description=COMMANDS[name])
        module.add_parser(command)
        command.formatter_class = HelpFormatter  # after the module's: every option shows its default
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    # Build only the requested subcommand's parser when we can tell which one it is.
    names = [argv[0]] if argv and argv[0] in COMMANDS else None
    parser = build_parser(names)
    # argparse's own usage errors print one line and raise SystemExit(2); --help / --version SystemExit(0).
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 2
    # vo-gym's own options (--help, --version) take no value, so the command's name is the first
    # token that spells it and the command's own arguments are all that follow.
    own = argv[argv.index(args.command) + 1:]
    return guarded(args.command, lambda: _run_command(args, own))


def _run_command(args: argparse.Namespace, own: list[str]) -> int:
    """Run ``args.command`` with its arguments, recording which of them ``own`` typed."""
    module = _command_module(args.command)
    setattr(args, GIVEN_OPTIONS, typed_options(module.add_parser, own, prog=f"vo-gym {args.command}"))
    return module.run(args)


if __name__ == "__main__":
    sys.exit(main())
