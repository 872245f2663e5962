"""The ``vo-gym`` command line, the top layer: ``stereovo`` < ``vo_gym`` < ``agents`` < ``vo_gym_cli``.

- :mod:`vo_gym_cli.main`: the console script (``vo-gym``, or ``python -m vo_gym_cli``), which builds
  the parser and runs one subcommand;
- :mod:`vo_gym_cli.commands.common`: what every command shares (argument types that name the flag,
  the usage error, the output-folder checks, the one-line hints for a missing extra);
- :mod:`vo_gym_cli.commands`: one module a subcommand (``vo``, ``baselines``, ``bench``, ``train``,
  ``evaluate``, ``sweep``), each with ``add_parser(parser)`` and ``run(args) -> int``.
"""
