"""Helpers for the command-line tests: the repository root and the one-line error check."""

from __future__ import annotations

from pathlib import Path

def exit_code(argv: list[str]) -> int:
    """``vo-gym ARGV``'s exit status, whether argparse exits or the command returns it."""
    from vo_gym_cli.main import main

    try:
        return main(argv)
    except SystemExit as exc:
        return exc.code


def one_line_error(capsys, command: str) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith(f"vo-gym {command}: error:") and "Traceback" not in err[0], err
    return err[0]


ROOT = Path(__file__).resolve().parents[2]
