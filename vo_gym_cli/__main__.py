"""``python -m vo_gym_cli ...``: the ``vo-gym`` console script without the installed entry point."""

import sys

from vo_gym_cli.main import main

sys.exit(main())
