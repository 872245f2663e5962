"""``vo-gym evaluate`` (vo_gym_cli.commands.evaluate and evaluate_images): shipped samplers found by
name, bad samplers and sources named in one line before computing, rendered images replayed to every agent."""

from __future__ import annotations

import csv
import json

import pytest

from tests.support.cli import one_line_error
from vo_gym_cli.main import main


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
    line = one_line_error(capsys, "evaluate")
    assert "--adaptive-sampler" in line and str(path) in line
    assert not out.exists() or not any(out.iterdir())


def test_evaluate_on_rendered_images_replays_the_same_frames_to_every_agent(tmp_path, capsys, short):
    argv = ["evaluate", "--source", "rendered", "--resolution", "vga", "--episodes", "1", "--frames-per-episode", "2",
            "--budgets", "1,4", "--agent", "uniform", "--agent", "oracle", "--agent", "adaptive-pg-prior",
            "--methods", "msac", "--seed", "4", "--no-progress"]
    assert main([*argv, "--out", str(tmp_path / "a")]) == 0
    with (tmp_path / "a" / "frames.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    # three agents (one of them in-frame) and one classical method, at two budgets, on two frames
    assert len(rows) == 4 * 2 * 2
    assert {r["agent"] for r in rows} == {"uniform", "oracle (upper bound)", "adaptive-pg-prior", "msac (fixed)"}
    assert all(int(r["n_hypotheses"]) == int(r["budget"]) for r in rows)
    summary = json.loads((tmp_path / "a" / "summary.json").read_text())
    assert summary["settings"]["env_id"] == "vo_gym/StereoVOImages-v0"
    cells = {(r["agent"], r["budget"]): r for r in summary["rows"]}
    oracle = cells[("oracle (upper bound)", 1)]
    assert oracle["success"] >= cells[("uniform", 1)]["success"] and oracle["ci_low"] <= oracle["success"] <= oracle["ci_high"]
    assert (tmp_path / "a" / "success_vs_budget.png").stat().st_size > 0
    assert "Wilson 95 %" in capsys.readouterr().out
    assert main([*argv, "--no-plots", "--out", str(tmp_path / "b")]) == 0  # same seed, same rows
    assert (tmp_path / "b" / "frames.csv").read_text() == (tmp_path / "a" / "frames.csv").read_text()


@pytest.mark.parametrize("source, needle", [("kitti:/data", "evaluate runs on rendered images"),
                                            ("bogus", "--source must be one of rendered")])
def test_evaluate_source_errors_are_one_line(tmp_path, capsys, source, needle):
    assert main(["evaluate", "--source", source, "--out", str(tmp_path / "e")]) == 2
    assert needle in one_line_error(capsys, "evaluate")
    assert not (tmp_path / "e").exists()


SWEEP = ["--episodes", "1", "--frames-per-episode", "2", "--n", "120", "--epsilons", "0.5", "--budget", "8",
         "--budgets", "8", "--sweep-epsilon", "0.5", "--methods", "msac", "--no-plots", "--no-progress",
         "--workers", "1", "--agent", "uniform", "--seed", "7"]


def test_the_outlier_preset_reaches_the_environment_and_the_record(tmp_path, capsys):
    assert main(["evaluate", *SWEEP, "--out", str(tmp_path / "default")]) == 0
    assert main(["evaluate", *SWEEP, "--outlier-preset", "hostile", "--out", str(tmp_path / "hostile")]) == 0
    summary = json.loads((tmp_path / "hostile" / "summary.json").read_text())
    assert summary["config"]["env_kwargs"] == {"outliers": "hostile"}
    assert json.loads((tmp_path / "default" / "summary.json").read_text())["config"]["env_kwargs"] == {}
    assert "Environment `vo_gym/StereoVO-v0`, outliers='hostile', N = 120" in (tmp_path / "hostile" / "summary.md").read_text()
    assert "Environment `vo_gym/StereoVO-v0`, N = 120" in (tmp_path / "default" / "summary.md").read_text()
    # the same seeds, other match errors: other rows
    assert (tmp_path / "default" / "frames.csv").read_text() != (tmp_path / "hostile" / "frames.csv").read_text()
    # the flag is the env keyword: given both ways, the same run
    argv = ["evaluate", *SWEEP, "--env-kwargs", '{"outliers": "hostile"}', "--outlier-preset", "hostile"]
    assert main([*argv, "--out", str(tmp_path / "both")]) == 0
    rows = lambda name: [line.rsplit(",", 3)[0] for line in (tmp_path / name / "frames.csv").read_text().splitlines()]  # noqa: E731
    assert rows("both") == rows("hostile")


@pytest.mark.parametrize("more, needle", [
    (["--env-kwargs", '{"outliers": "default"}', "--outlier-preset", "hostile"],
     "--outlier-preset hostile contradicts --env-kwargs' outliers='default'"),
    (["--adaptive", "--outlier-preset", "hostile"], "--outlier-preset applies to the sweeps on simulated matches"),
    (["--source", "rendered", "--outlier-preset", "hostile"], "not with --source"),
])
def test_an_outlier_preset_that_cannot_apply_is_one_line(tmp_path, capsys, more, needle):
    assert main(["evaluate", *SWEEP, *more, "--out", str(tmp_path / "e")]) == 2
    assert needle in one_line_error(capsys, "evaluate")
    assert not (tmp_path / "e").exists()
