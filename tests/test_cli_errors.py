"""Command-line errors: every bad argument or unusable path is one line naming it, exit 2, no traceback,
checked before any computing; Ctrl-C is one line and exit 130; --version, help with defaults; vo runs
every method it lists and a learned sampler by name."""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import pytest

from vo_gym_cli import main as cli
from vo_gym_cli.main import main


def _one_line(capsys, command: str) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith(f"vo-gym {command}: error:") and "Traceback" not in err[0], err
    return err[0]


@pytest.mark.parametrize("command, argv, needle", [
    ("bench", ["--ns", "-1"], "--ns"), ("bench", ["--ns", "2"], "--ns"), ("bench", ["--epsilons", "2"], "--epsilons"),
    ("bench", ["--noise", "-1"], "--noise"), ("bench", ["--seed", "-1"], "--seed"), ("bench", ["--frames", "x"], "--frames"),
    ("vo", ["--seed", "-1"], "--seed"), ("vo", ["--noise", "nan"], "--noise"), ("vo", ["--n", "2"], "--n"),
    ("vo", ["--auc", "inf"], "--auc"), ("train", ["--seed", "-1"], "--seed"), ("train", ["--epsilon", "2"], "--epsilon"),
    ("train", ["--gamma", "1.5"], "--gamma"), ("train", ["--n-envs", "0"], "--n-envs"),
    ("train", ["--timesteps", "1e3"], "--timesteps"), ("train", ["--lr", "-1"], "--lr"),
])
def test_bad_arguments_are_one_line_naming_them(tmp_path, capsys, command, argv, needle):
    with pytest.raises(SystemExit) as exc:
        main([command, *argv, "--out", str(tmp_path / "out")])
    assert exc.value.code == 2
    assert needle in _one_line(capsys, command)
    assert not (tmp_path / "out").exists()


def test_train_unknown_env_id_is_a_usage_error(tmp_path, capsys):
    assert main(["train", "--algo", "ppo", "--env-id", "foo", "--out", str(tmp_path / "t")]) == 2
    line = _one_line(capsys, "train")
    assert "--env-id 'foo'" in line and "vo_gym/StereoVO-v0" in line


@pytest.mark.parametrize("command, extra", [
    ("vo", ["--frames", "2", "--no-progress"]),
    ("bench", ["--frames", "1", "--ns", "60", "--epsilons", "0.2", "--no-peers"]),
    ("train", ["--frames", "1", "--no-progress"]),
])
@pytest.mark.parametrize("kind", ["file", "under a file"])
def test_unusable_out_is_refused_before_computing(tmp_path, capsys, monkeypatch, command, extra, kind):
    blocker = tmp_path / "a-file"
    blocker.write_text("x")
    out = blocker if kind == "file" else blocker / "sub"
    if command == "bench":  # bench's --out is a CSV file: a folder, or a file under a file, is unusable
        out = tmp_path if kind == "file" else blocker / "sub.csv"
    # Computing would call the simulator: make it fail loudly, to prove the check comes first.
    import stereovo.simulation as simulation

    def never(*args, **kwargs):
        raise AssertionError("computing started before --out was checked")

    monkeypatch.setattr(simulation, "simulate_frame", never)
    monkeypatch.setattr(simulation.Sequence, "frame", never)
    assert main([command, *extra, "--out", str(out)]) == 2
    assert "--out" in _one_line(capsys, command)


def test_ctrl_c_is_one_line_and_exit_130(monkeypatch, capsys):
    from vo_gym_cli.commands import vo

    def interrupted(args: argparse.Namespace) -> int:
        raise KeyboardInterrupt

    monkeypatch.setattr(vo, "run", interrupted)
    assert main(["vo", "--frames", "1"]) == 130
    assert capsys.readouterr().err.strip() == "vo-gym vo: interrupted"


def test_version_and_top_level_help(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.startswith("vo-gym ")
    with pytest.raises(SystemExit):
        main(["--help"])
    text = capsys.readouterr().out
    assert "Gymnasium" in text and "issue" not in text.lower()
    assert all(name in text for name in cli.COMMANDS)


@pytest.mark.parametrize("command", ["vo", "bench", "train"])
def test_every_option_has_help_with_its_default(command):
    parser = cli.build_parser([command])
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices[command]
    formatter = sub.formatter_class(prog="x")
    for action in sub._actions:
        if not action.option_strings or action.dest == "help":
            continue
        assert action.help, f"{command} {action.option_strings} has no help"
        text = formatter._get_help_string(action)
        if action.nargs != 0:  # a flag's default is off
            assert "default" in text, f"{command} {action.option_strings}: no default in {text!r}"


def test_the_catalog_names_every_shipped_file_and_loads_no_torch():
    code = (
        "import sys; from agents import catalog\n"
        "names = catalog.ONE_SHOT_SAMPLERS + catalog.IN_FRAME_SAMPLERS\n"
        "print(all(catalog.shipped_file(n).is_file() for n in names), [catalog.sampler_kind(n) for n in names],"
        " 'torch' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split(None, 1)[0] == "True" and out.stdout.rstrip().endswith("False")
    assert out.stdout.count("'one-shot'") == 4 and out.stdout.count("'in-frame'") == 2
    shipped = {p.stem for p in (Path(__file__).resolve().parents[1] / "agents" / "checkpoints").glob("*.pt")}
    from agents import catalog

    assert shipped == set(catalog.ONE_SHOT_SAMPLERS + catalog.IN_FRAME_SAMPLERS)
    with pytest.raises(ValueError, match="unknown shipped sampler 'nope'; shipped: ngransac-supervised"):
        catalog.sampler_kind("nope")


@pytest.mark.parametrize("argv", [["--method", "prosac"], ["--method", "guided-mlesac"],
                                  ["--method", "msac", "--agent", "ngransac-supervised"]])
def test_vo_runs_score_methods_and_learned_samplers(tmp_path, capsys, argv):
    out = tmp_path / "vo"
    assert main(["vo", *argv, "--frames", "4", "--n", "150", "--no-progress", "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["metrics"]["frames"] == 4 and summary["metrics"]["success_rate"] > 0
    assert (out / "trajectory_est.tum").read_text().count("\n") == 5


def test_vo_agent_errors_are_one_line(tmp_path, capsys):
    assert main(["vo", "--agent", "nope", "--frames", "2", "--out", str(tmp_path / "v")]) == 2
    assert "--agent" in _one_line(capsys, "vo")
    assert main(["vo", "--agent", "ppo", "--method", "inlier-detection", "--frames", "2",
                 "--out", str(tmp_path / "v")]) == 2
    assert "does not sample" in _one_line(capsys, "vo")


def test_evaluate_finds_a_shipped_sampler_by_name():
    from agents.evaluation.setup import resolve_agent

    spec = resolve_agent("ngransac-supervised")
    assert spec.kind == "checkpoint" and spec.label == "ngransac-supervised"


@pytest.mark.parametrize("content", [None, b"not a checkpoint", b"PK\x03\x04 truncated"])
def test_a_bad_adaptive_sampler_is_named_before_computing(tmp_path, capsys, content):
    path = tmp_path / "sampler.pt"
    if content is not None:
        path.write_bytes(content)
    out = tmp_path / "out"
    assert main(["evaluate", "--adaptive", "--adaptive-sampler", str(path), "--out", str(out)]) == 2
    line = _one_line(capsys, "evaluate")
    assert "--adaptive-sampler" in line and str(path) in line
    assert not out.exists() or not any(out.iterdir())


def test_only_the_pool_exit_race_is_silenced_after_an_interrupt(monkeypatch):
    """After Ctrl-C, CPython 3.11's process-pool exit hook may hit its closed pipe; that, and only that, stays quiet."""
    import types

    from vo_gym_cli.commands.common import quiet_pool_exit

    def unraisable(filename, error):
        code = compile("def boom(e):\n    raise e\n", filename, "exec")
        scope: dict = {}
        exec(code, scope)  # noqa: S102 - a test-made function whose frame names the given file
        try:
            scope["boom"](error)
        except Exception as err:  # noqa: BLE001
            return types.SimpleNamespace(exc_type=type(err), exc_value=err, exc_traceback=err.__traceback__,
                                         err_msg=None, object=None)

    passed = []
    monkeypatch.setattr("sys.__unraisablehook__", passed.append)
    quiet_pool_exit(unraisable("/usr/lib/python3.11/concurrent/futures/process.py", OSError(9, "Bad file descriptor")))
    assert passed == []
    other = unraisable("/somewhere/else.py", OSError(9, "Bad file descriptor"))
    quiet_pool_exit(other)
    not_os = unraisable("/usr/lib/python3.11/concurrent/futures/process.py", ValueError("x"))
    quiet_pool_exit(not_os)
    assert passed == [other, not_os]
