"""Edits of a checkpoint's payload shared by the tests of hostile checkpoint files."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable, Iterable

import pytest


def set_first_weight(key: str, value: float) -> Callable[[dict[str, Any]], None]:
    """An edit of a payload that sets the first entry of its ``state_dict[key]`` tensor to ``value``
    (a NaN or an infinity), on a copy of that tensor."""
    def edit(payload: dict[str, Any]) -> None:
        payload["state_dict"][key] = payload["state_dict"][key].clone()
        payload["state_dict"][key].view(-1)[0] = value
    return edit


def assert_refused_everywhere(path: Path, what: str, loads: Iterable[Callable[[Path], Any]],
                              commands: dict[str, list[str]], tmp_path: Path, capsys) -> None:
    """Each of ``loads`` refuses the file at ``path`` within 5 s (checked from the declared sizes, before
    anything is built) with a one-line CheckpointError that names the file and ``what``; so does
    ``agents.LearnedEstimator`` (a ValueError); and each command line of ``commands`` (name -> argv,
    without ``--out``) prints one such line, exits 2 and leaves its ``--out`` empty."""
    import agents
    from agents.checkpoint import CheckpointError
    from vo_gym_cli.main import main

    for load in loads:
        with pytest.raises(CheckpointError) as err:
            load(path)
        message = str(err.value)
        assert message.startswith(f"checkpoint {path}") and what in message and "\n" not in message, message
    with pytest.raises(ValueError) as err:
        agents.LearnedEstimator(str(path))
    assert str(path) in str(err.value) and what in str(err.value) and "\n" not in str(err.value)
    capsys.readouterr()
    for command, argv in commands.items():
        out = tmp_path / f"out-{command.replace(' ', '')}"
        assert main([*argv, "--out", str(out)]) == 2, command
        lines = capsys.readouterr().err.strip().splitlines()
        assert len(lines) == 1 and str(path) in lines[0] and what in lines[0] and "Traceback" not in lines[0], (
            command, lines)
        assert not out.exists() or not any(out.iterdir()), command
