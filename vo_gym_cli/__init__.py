"""The ``vo-gym`` command line, the top layer: ``stereovo`` < ``vo_gym`` < ``agents`` < ``vo_gym_cli``.

- :mod:`vo_gym_cli.main`: the console script (``vo-gym``, or ``python -m vo_gym_cli``), which builds
  the parser and runs one subcommand;
- :mod:`vo_gym_cli.commands.arguments`: the argument types every command shares, each refusing a
  bad value in one line naming the flag;
- :mod:`vo_gym_cli.commands.common`: what else every command shares (the usage error, the record of
  the options typed, the output-folder checks, the one-line hints for a missing extra);
- :mod:`vo_gym_cli.commands`: one module a subcommand (``vo``, ``baselines``, ``bench``, ``train``,
  ``evaluate``, ``sweep``), each with ``add_parser(parser)`` and ``run(args) -> int``.
"""
