"""Helpers for the command-line tests: the repository root and the one-line error check."""

from __future__ import annotations

from pathlib import Path

def one_line_error(capsys, command: str) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith(f"vo-gym {command}: error:") and "Traceback" not in err[0], err
    return err[0]


ROOT = Path(__file__).resolve().parents[2]
