"""The ``vo-gym`` console script: one subcommand a module under ``vo_gym.commands``.

Each command module exposes ``add_parser(subparsers)`` (declares its options)
and ``run(args) -> int`` (does the work, returns the exit code). Modules are
imported lazily so that ``vo-gym --help`` stays fast and a command's heavy
imports (torch, matplotlib) load only when it runs.
"""

from __future__ import annotations

import argparse
import importlib
import sys

COMMANDS = {
    "vo": "Run stereo visual odometry over a simulated sequence.",
    "baselines": "Evaluate the classical RANSAC family on a benchmark grid.",
    "bench": "Time the estimator core (and optional peers) on identical frames.",
    "train": "Train a learned sampling policy.",
    "evaluate": "Compare agents and classical methods on held-out seeds.",
    "sweep": "Sweep the NG-RANSAC or PPO trainer's hyperparameters on Ray Tune (a YAML search space).",
}


def _command_module(name: str):
    return importlib.import_module(f"vo_gym.commands.{name}")


def build_parser(names: list[str] | None = None) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="vo-gym", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in names or COMMANDS:
        try:
            module = _command_module(name)
        except ModuleNotFoundError as err:
            if err.name != f"vo_gym.commands.{name}":
                raise
            continue
        module.add_parser(sub.add_parser(name, help=COMMANDS[name], description=COMMANDS[name]))
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    # Build only the requested subcommand's parser when we can tell which one it is.
    names = [argv[0]] if argv and argv[0] in COMMANDS else None
    parser = build_parser(names)
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 2
    return int(_command_module(args.command).run(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
