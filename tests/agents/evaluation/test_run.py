"""agents.evaluation.run (``vo-gym evaluate``): same frames for every agent, tables and plots,
determinism, clear errors, and learned agents run with the adaptive stop beside the classical rows."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from agents.checkpoint import save_checkpoint
from agents.evaluation.report import ADAPTIVE_KINDS
from agents.evaluation.run import episode_frames
from agents.evaluation.setup import EvalConfig, resolve_agent
from agents.network import CorrespondenceNet
from agents.policies import make_heuristic
from agents.rollout import make_env
from vo_gym import N_FEATURES, StereoVOEnv
from vo_gym_cli.main import main


TINY = ["--episodes", "2", "--frames-per-episode", "3", "--n", "100", "--epsilons", "0.5,0.85", "--budget", "8",
        "--budgets", "2,8", "--sweep-epsilon", "0.85", "--methods", "msac,guided", "--no-progress"]


def _strip_time(rows):
    return [{k: v for k, v in r.items() if k != "time_s"} for r in rows]


def _read_rows(path):
    import csv

    with open(path, newline="") as fh:
        return _strip_time(list(csv.DictReader(fh)))


def _strip_summary_times(summary):
    text = json.dumps({k: v for k, v in summary.items() if k not in ("wall_s",)}, sort_keys=True)
    data = json.loads(text)

    def walk(node):
        if isinstance(node, dict):
            return {k: walk(v) for k, v in node.items() if k != "median_time_ms"}
        if isinstance(node, list):
            return [walk(v) for v in node]
        return node

    return walk(data)


def test_frames_depend_only_on_the_seed():
    kwargs = dict(n_frames=4, n_correspondences=60, outlier_ratio=0.6, budget=4)
    seen = []
    for agent in ("uniform", "oracle"):
        env = StereoVOEnv(**kwargs)
        obs, _ = env.reset(seed=11)
        frames, done = [], False
        while not done:
            frame = env.current_frame
            frames.append(frame)
            action = (np.where(frame.truth.inlier, 10.0, -10.0) if agent == "oracle"
                      else make_heuristic(agent).act(obs))
            obs, _, _, done, _ = env.step(action)
        seen.append(frames)
    seen.append(episode_frames(make_env("vo_gym/StereoVO-v0", **kwargs), 11))
    for other in seen[1:]:
        assert len(other) == len(seen[0]) == 4
        for a, b in zip(seen[0], other):
            assert a.index == b.index
            np.testing.assert_array_equal(a.prev, b.prev)
            np.testing.assert_array_equal(a.curr, b.curr)
            np.testing.assert_array_equal(a.scores, b.scores)
            np.testing.assert_array_equal(a.truth.inlier, b.truth.inlier)


def test_evaluate_heuristics_writes_tables_and_plots_and_is_reproducible(tmp_path, capsys):
    torch.manual_seed(0)
    ckpt = save_checkpoint(tmp_path / "net.pt", CorrespondenceNet(N_FEATURES, 8, 1), {"algo": "test"})
    agents = ["--agent", "uniform", "--agent", "consistency", "--agent", "oracle", "--agent", str(ckpt)]
    out_a, out_b = tmp_path / "a", tmp_path / "b"
    assert main(["evaluate", *agents, *TINY, "--workers", "1", "--out", str(out_a)]) == 0
    printed = capsys.readouterr().out
    assert "(a) Success rate vs contamination" in printed and "oracle (upper bound)" in printed
    assert "Hypotheses needed for 99 % success" in printed
    for name in ("frames.csv", "summary.json", "summary.md", "success_vs_epsilon.png", "success_vs_budget.png"):
        assert (out_a / name).is_file(), name

    summary = json.loads((out_a / "summary.json").read_text())
    names = [m["name"] for m in summary["methods"]]
    assert names == ["uniform", "consistency", "net", "oracle (upper bound)", "msac (fixed)",
                     "ransac+guided (fixed)", "msac (adaptive)", "ransac+guided (adaptive)",
                     "msac (adaptive, textbook)", "ransac+guided (adaptive, textbook)"]
    eps = summary["epsilon_sweep"]["methods"]
    assert eps["oracle (upper bound)"]["0.85"]["success_rate"] > eps["uniform"]["0.85"]["success_rate"]
    assert eps["oracle (upper bound)"]["0.85"]["frames"] == 6
    assert set(summary["budget_sweep"]["methods"]["uniform"]) == {"2", "8"}
    assert set(summary["budget_sweep"]["adaptive"]) == {"msac (adaptive)", "ransac+guided (adaptive)",
                                                         "msac (adaptive, textbook)",
                                                         "ransac+guided (adaptive, textbook)"}
    # Hypotheses for 99 % success, worked out from frames.csv: for each row that runs at a budget (not on its own
    # stop), the smallest budget whose frames at the sweep's contamination succeed at least 99 % of the time.
    frames = _read_rows(out_a / "frames.csv")
    at_a_budget = {r["method"] for r in frames if r["kind"] not in ADAPTIVE_KINDS}
    expected = {}
    for method in at_a_budget:
        rates = {b: np.mean([r["success"] == "True" for r in frames
                             if (r["method"], float(r["epsilon"]), int(r["budget"])) == (method, 0.85, b)])
                 for b in (2, 8)}
        expected[method] = min((b for b in (2, 8) if rates[b] >= 0.99), default=None)
    needed = summary["hypotheses_for_success"]["methods"]
    assert needed == expected and "msac (adaptive)" not in needed
    assert expected["oracle (upper bound)"] is not None  # the oracle reaches it within the budgets

    # Same seed, other worker count: the same numbers (wall time aside).
    assert main(["evaluate", *agents, *TINY, "--workers", "2", "--out", str(out_b), "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert _strip_summary_times(printed) == _strip_summary_times(summary)
    assert _read_rows(out_a / "frames.csv") == _read_rows(out_b / "frames.csv")


def test_classical_rows_use_the_agents_frames():
    from agents.evaluation.run import run_agent_episode, run_classical_episode, classical_estimators_for
    from agents.evaluation.setup import AgentSpec

    config = EvalConfig(episodes=1, frames_per_episode=2, n=60, methods=("msac",))
    kwargs = config.env_kwargs_for(0.5, 4)
    agent_rows = run_agent_episode(AgentSpec("uniform", "heuristic", "uniform"), config.env_id, kwargs, 7)
    classical = run_classical_episode(classical_estimators_for(config, 4, adaptive=True), config.env_id, kwargs, 7)
    assert [r["frame"] for r in classical] == [1, 1, 1, 2, 2, 2]
    for a, c in zip(agent_rows, classical[::3]):
        assert (a["frame"], a["n_true_inliers"], a["frame_outlier_ratio"]) == (
            c["frame"], c["n_true_inliers"], c["frame_outlier_ratio"])
    assert {r["method"] for r in classical} == {"msac (fixed)", "msac (adaptive)", "msac (adaptive, textbook)"}
    assert all(r["n_hypotheses"] == 4 for r in classical if r["method"] == "msac (fixed)")


def test_adaptive_classical_rows_run_the_environments_recipe_beside_the_textbook_one():
    from agents.evaluation.run import classical_estimators_for
    from vo_gym.env import DEFAULT_ESTIMATOR_OPTIONS

    config = EvalConfig(episodes=1, frames_per_episode=2, n=60, methods=("ransac",), max_iterations=500)
    rows = {label: (kind, est) for label, kind, est in classical_estimators_for(config, 8, adaptive=True)}
    assert set(rows) == {"ransac (fixed)", "ransac (adaptive)", "ransac (adaptive, textbook)"}
    recipe, textbook = rows["ransac (adaptive)"][1], rows["ransac (adaptive, textbook)"][1]
    assert rows["ransac (adaptive)"][0] == "classical, adaptive"
    assert rows["ransac (adaptive, textbook)"][0] == "classical, adaptive, textbook"
    assert dict(recipe.options) == {**DEFAULT_ESTIMATOR_OPTIONS, "max_iterations": 500}
    assert dict(textbook.options) == {"max_iterations": 500}


def test_checkpoint_with_another_feature_layout_is_refused(tmp_path, capsys):
    path = save_checkpoint(tmp_path / "old.pt", CorrespondenceNet(N_FEATURES, 8, 1), {"algo": "test"})
    payload = torch.load(path, weights_only=False)
    payload["feature_names"] = payload["feature_names"][:-1]
    payload["feature_layout_version"] = 0
    torch.save(payload, path)
    with pytest.raises(ValueError, match="another feature layout"):
        resolve_agent(str(path))
    assert main(["evaluate", "--agent", str(path), *TINY, "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "vo-gym evaluate: error:" in err and "feature layout" in err
    assert not (tmp_path / "out").exists()


def test_unknown_agent_and_missing_checkpoint_exit_non_zero(tmp_path, capsys):
    assert main(["evaluate", "--agent", "clever-agent", *TINY, "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "unknown agent 'clever-agent'" in err and "uniform" in err
    assert main(["evaluate", "--agent", str(tmp_path / "nope.pt"), *TINY, "--out", str(tmp_path)]) == 2
    assert "no checkpoint at" in capsys.readouterr().err
    assert main(["evaluate", "--agent", "uniform", *TINY[:-3], "--methods", "magic", "--out", str(tmp_path)]) == 2
    assert "unknown classical method(s): magic" in capsys.readouterr().err


def test_interrupt_then_resume_writes_the_uninterrupted_files(tmp_path, capsys, monkeypatch):
    import agents.evaluation.run as evaluation

    argv = ["evaluate", "--agent", "uniform", *TINY, "--methods", "msac", "--workers", "1", "--no-plots"]
    whole, out = tmp_path / "whole", tmp_path / "run"
    assert main([*argv, "--out", str(whole)]) == 0
    n_units = len(evaluation.evaluation_units(
        EvalConfig(episodes=2, frames_per_episode=3, n=100, epsilons=(0.5, 0.85), budget=8, budgets=(2, 8),
                   sweep_epsilon=0.85, methods=("msac",)), [resolve_agent("uniform")]))
    # every unit is one episode of an agent or of the classical methods: the sixth is interrupted
    calls = []

    def stop_at_unit_5(real):
        def run(*args, **kwargs):
            calls.append(args)
            if len(calls) == 6:
                raise KeyboardInterrupt
            return real(*args, **kwargs)
        return run

    with monkeypatch.context() as patch:
        for name in ("run_agent_episode", "run_classical_episode"):
            patch.setattr(evaluation, name, stop_at_unit_5(getattr(evaluation, name)))
        capsys.readouterr()
        assert main([*argv, "--out", str(out)]) == 130
    assert capsys.readouterr().err.strip().splitlines() == [
        f"interrupted: 5 of {n_units} trials saved in {out}; rerun with --resume"]
    assert main([*argv, "--out", str(out)]) == 2  # not empty: refused without --resume
    assert "--resume" in capsys.readouterr().err
    assert main([*argv, "--out", str(out), "--resume"]) == 0
    assert _read_rows(out / "frames.csv") == _read_rows(whole / "frames.csv")
    a, b = (json.loads((d / "summary.json").read_text()) for d in (out, whole))
    assert _strip_summary_times(a) == _strip_summary_times(b)


def test_evaluate_runs_agents_adaptively_beside_the_classical_adaptive_rows():
    from agents.evaluation.run import run_evaluation
    from agents.evaluation.setup import KIND_AGENT_ADAPTIVE, EvalConfig, resolve_agents

    config = EvalConfig(episodes=1, frames_per_episode=3, epsilons=(0.7,), budgets=(16,), budget=16,
                        sweep_epsilon=0.7, n=200, methods=("prosac",), max_iterations=500, adaptive_agents=True)
    result = run_evaluation(config, resolve_agents(["match-score"]), workers=1, progress=False)
    adaptive = [r for r in result.rows if r["method"] == "match-score (adaptive)"]
    fixed = [r for r in result.rows if r["method"] == "match-score"]
    assert len(adaptive) == len(fixed) == 3 * 1  # the fixed-budget setting only (sweep eps = eps)
    assert all(r["kind"] == KIND_AGENT_ADAPTIVE and r["budget"] == 16 for r in adaptive)
    assert all(r["n_hypotheses"] == 16 for r in fixed)
    assert all(1 <= r["n_hypotheses"] <= 500 for r in adaptive) and any(r["n_hypotheses"] != 16 for r in adaptive)
    table = result.summary["budget_sweep"]["adaptive"]
    assert {"prosac (adaptive)", "match-score (adaptive)"} <= set(table)
    with pytest.raises(ValueError, match="adaptive_agents"):
        EvalConfig(adaptive_agents=1)


def test_an_in_frame_sampler_is_evaluated_on_the_agents_frames_at_each_budget_and_under_its_own_stop(tmp_path):
    import shutil
    from pathlib import Path

    from agents.evaluation.run import run_evaluation
    from agents.evaluation.setup import IN_FRAME_KIND, KIND_AGENT, KIND_AGENT_ADAPTIVE, resolve_agents

    mine = tmp_path / "mine.pt"
    shutil.copy(Path(__file__).parents[3] / "agents" / "checkpoints" / "adaptive-pg.pt", mine)
    agents = resolve_agents(["adaptive-pg-prior", str(mine), "uniform"])
    assert [(a.label, a.kind) for a in agents[:2]] == [("adaptive-pg-prior", IN_FRAME_KIND), ("mine", IN_FRAME_KIND)]
    config = EvalConfig(episodes=1, frames_per_episode=3, epsilons=(0.8,), budgets=(2, 8), budget=8,
                        sweep_epsilon=0.8, n=200, methods=(), max_iterations=300, adaptive_agents=True)
    result = run_evaluation(config, agents, workers=1, progress=False)
    rows = {(r["method"], r["budget"], r["frame"]): r for r in result.rows}
    uniform = [r for r in result.rows if r["method"] == "uniform" and r["budget"] == 8]
    for label in ("adaptive-pg-prior", "mine"):
        for budget in (2, 8):
            fixed = [rows[(label, budget, k)] for k in (1, 2, 3)]
            assert all(r["kind"] == KIND_AGENT and r["n_hypotheses"] == budget for r in fixed)
        own = [rows[(f"{label} (adaptive)", 8, k)] for k in (1, 2, 3)]
        assert all(r["kind"] == KIND_AGENT_ADAPTIVE and 1 <= r["n_hypotheses"] <= 64 for r in own)
    # the same frames as the env agents'
    for a, u in zip([rows[("adaptive-pg-prior", 8, k)] for k in (1, 2, 3)], uniform):
        assert (a["n_true_inliers"], a["frame_outlier_ratio"]) == (u["n_true_inliers"], u["frame_outlier_ratio"])
    # the in-frame sampler at 8 hypotheses beats uniform sampling at eps 0.8 on these frames
    assert sum(rows[("adaptive-pg-prior", 8, k)]["success"] for k in (1, 2, 3)) >= sum(u["success"] for u in uniform)
    # rows are a function of the seed
    again = run_evaluation(config, agents, workers=1, progress=False)
    assert _strip_time(again.rows) == _strip_time(result.rows)
