"""``vo-gym evaluate`` (vo_gym_cli.commands.evaluate and evaluate_images): shipped samplers found by
name, bad samplers and sources named in one line before computing, rendered images replayed to every agent,
an option the chosen run would ignore refused, and the score AUC one value from the flags to the header."""

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


@pytest.mark.parametrize("argv, needle", [
    ([*SWEEP, "--env-kwargs", '{"outliers": "default"}', "--outlier-preset", "hostile"],
     "--outlier-preset hostile contradicts --env-kwargs' outliers='default'"),
    (["--adaptive", "--outlier-preset", "hostile"], "--outlier-preset hostile applies to the sweeps on simulated matches"),
    (["--source", "rendered", "--outlier-preset", "hostile"], "not with --source"),
])
def test_an_outlier_preset_that_cannot_apply_is_one_line(tmp_path, capsys, argv, needle):
    assert main(["evaluate", *argv, "--out", str(tmp_path / "e")]) == 2
    assert needle in one_line_error(capsys, "evaluate")
    assert not (tmp_path / "e").exists()


def test_an_auc_is_one_value_from_the_flags_to_the_frames_and_the_header(tmp_path, capsys):
    assert main(["evaluate", *SWEEP, "--auc", "0.6", "--env-kwargs", '{"score_auc": 0.9}', "--out", str(tmp_path / "e")]) == 2
    assert "--auc 0.6 contradicts --env-kwargs' score_auc=0.9; set it with --auc alone" in one_line_error(capsys, "evaluate")
    assert not (tmp_path / "e").exists()
    for name, more, auc in (("flag", ["--auc", "0.6"], "0.6"), ("kwarg", ["--env-kwargs", '{"score_auc": 0.9}'], "0.9"),
                            ("both", ["--auc", "0.9", "--env-kwargs", '{"score_auc": 0.9}'], "0.9"), ("neither", [], "0.75")):
        assert main(["evaluate", *SWEEP, *more, "--out", str(tmp_path / name)]) == 0
        with (tmp_path / name / "frames.csv").open() as fh:
            assert {row["score_auc"] for row in csv.DictReader(fh)} == {auc}, name
        header = (tmp_path / name / "summary.md").read_text().splitlines()[2]
        assert f"N = 120, score AUC {auc}, 1 episodes" in header and "score_auc=" not in header, header


def test_an_env_keyword_that_contradicts_the_hypothesis_cap_is_refused(tmp_path, capsys):
    argv = ["evaluate", *SWEEP, "--max-iterations", "2000", "--env-kwargs", '{"max_iterations": 50}',
            "--out", str(tmp_path / "e")]
    assert main(argv) == 2
    assert "--max-iterations 2000 contradicts --env-kwargs' max_iterations=50" in one_line_error(capsys, "evaluate")
    assert not (tmp_path / "e").exists()
    # the keyword alone is the cap (the flag's default does not contradict it)
    argv = ["evaluate", *SWEEP, "--env-kwargs", '{"max_iterations": 50}', "--out", str(tmp_path / "k")]
    assert main(argv) == 0
    assert json.loads((tmp_path / "k" / "summary.json").read_text())["config"]["max_iterations"] == 50


@pytest.mark.parametrize("env_id, needle", [
    ("vo_gym/StereoVOAdaptive-v0", "--env-id vo_gym/StereoVOAdaptive-v0 is an in-frame environment"),
    ("vo_gym/StereoVOAdaptiveHard-v0", "in-frame samplers are compared with --adaptive"),
    ("vo_gym/StereoVOImages-v0", "--env-id vo_gym/StereoVOImages-v0 is an image environment; evaluate on rendered"
                                 " images with --source rendered"),
])
def test_an_env_id_the_sweeps_cannot_step_is_refused_before_the_header(tmp_path, capsys, env_id, needle):
    assert main(["evaluate", *SWEEP, "--env-id", env_id, "--out", str(tmp_path / "e")]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and len(captured.err.strip().splitlines()) == 1 and needle in captured.err
    assert not (tmp_path / "e").exists()


ENV = "environment 'vo_gym/StereoVO-v0': "


@pytest.mark.parametrize("more, needle", [
    # the message names outlier_ratio (a noise_sigma too large *when frames have outliers*): read from the
    # text, it was blamed on --epsilons / --sweep-epsilon
    (["--env-kwargs", '{"noise_sigma": 300}'], f"--env-kwargs: {ENV}StereoVOEnv: invalid simulator setting: "
                                               "SimulationConfig.noise_sigma must be small enough"),
    # the message has none of the words the text was searched for: it was blamed on --env-id
    (["--env-kwargs", '{"method": "nosac"}'], f"--env-kwargs: {ENV}StereoVOEnv: method: unknown method 'nosac'"),
    (["--env-kwargs", '{"hypothesis_cost": 2}'], f"--env-kwargs: {ENV}StereoVOEnv: hypothesis_cost must be"),
    (["--env-kwargs", '{"noise_sigmaa": 1}'], f"--env-kwargs: {ENV}StereoVOEnv got unexpected keyword argument(s)"),
    (["--env-kwargs", '{"score_auc": 1.5}'], f"--env-kwargs: {ENV}StereoVOEnv: invalid simulator setting: "
                                             "SimulationConfig.score_auc must be"),
    # the AUC of the flag is checked as the config's field, by the simulator's rule
    (["--auc", "1.5"], "--auc must be a finite number in [0.5, 1), got 1.5"),
    (["--auc", "nan"], "--auc must be a finite number in [0.5, 1), got nan"),
    (["--env-id", "vo_gym/StereoVO-v1"], "--env-id: environment 'vo_gym/StereoVO-v1': "),
])
def test_an_environments_refusal_names_the_option_that_set_the_refused_keyword(tmp_path, capsys, more, needle):
    assert main(["evaluate", *SWEEP, *more, "--out", str(tmp_path / "e")]) == 2
    line = one_line_error(capsys, "evaluate")
    assert line.startswith(f"vo-gym evaluate: error: {needle}"), line
    assert not (tmp_path / "e").exists()


@pytest.mark.parametrize("more, refused, flag", [
    (["--epsilons", "0.3,0.6"], ("outlier_ratio", 0.6), "--epsilons"),
    (["--sweep-epsilon", "0.7"], ("outlier_ratio", 0.7), "--sweep-epsilon"),
    (["--auc", "0.6"], ("score_auc", 0.6), "--auc"),
    (["--budget", "8", "--budgets", "4,16"], ("budget", 16), "--budgets"),
    (["--budget", "8"], ("budget", 8), "--budget"),
    (["--n", "90"], ("n_correspondences", 90), "--n"),
    (["--frames-per-episode", "3"], ("n_frames", 3), "--frames-per-episode"),
    (["--env-kwargs", '{"noise_sigma": 0.7}'], ("noise_sigma", 0.7), "--env-kwargs"),
    ([], None, "--env-id"),  # refused whatever the keywords: the id's own
])
def test_the_refused_keyword_is_found_by_building_not_by_reading_the_message(tmp_path, capsys, monkeypatch, more,
                                                                             refused, flag):
    # An environment that refuses one keyword's value in words that name no keyword (and say "must"): the
    # option is the one whose keyword, added to the id's own, the environment refuses.
    import agents.evaluation.run as run

    real = run.make_env

    def make_env(env_id, **kwargs):
        if refused is None or kwargs.get(refused[0]) == refused[1]:
            raise ValueError("StereoVOEnv: this must wait for a later version")
        return real(env_id, **kwargs)

    monkeypatch.setattr(run, "make_env", make_env)
    assert main(["evaluate", *SWEEP, *more, "--out", str(tmp_path / "e")]) == 2
    assert one_line_error(capsys, "evaluate") == (f"vo-gym evaluate: error: {flag}: {ENV}StereoVOEnv: this must wait "
                                                  "for a later version")
    assert not (tmp_path / "e").exists()


def test_check_environments_names_the_config_field_in_its_error():
    from agents.evaluation.run import check_environments
    from agents.evaluation.setup import EvalConfig
    from vo_gym.settings import FieldError

    with pytest.raises(FieldError) as err:
        check_environments(EvalConfig(episodes=1, frames_per_episode=1, epsilons=(0.0,), sweep_epsilon=0.8, n=60,
                                      budgets=(4,), env_kwargs={"noise_sigma": 300}, methods=("msac",)))
    # frames without outliers need no outlier threshold; the budget sweep's (eps 0.8) do: refused there
    assert err.value.field == "env_kwargs" and str(err.value).startswith(f"{ENV}StereoVOEnv: invalid simulator")
    with pytest.raises(FieldError) as err:
        check_environments(EvalConfig(env_id="vo_gym/StereoVO-v9", methods=("msac",)))
    assert err.value.field == "env_id" and str(err.value).startswith("environment 'vo_gym/StereoVO-v9': ")


ADAPTIVE = ["--adaptive", "--episodes", "1", "--frames-per-episode", "1"]


@pytest.mark.parametrize("more, needle", [
    (["--methods", "msac"], "--methods msac applies to the sweeps on simulated matches and --source rendered, not with"
                            " --adaptive (its samplers and settings are fixed"),
    (["--epsilons", "0.5"], "--epsilons 0.5 applies to the sweeps on simulated matches, not with --adaptive"),
    (["--budgets", "4,8"], "--budgets 4,8 applies to the sweeps on simulated matches and --source rendered"),
    (["--workers", "2"], "--workers 2 applies to the sweeps on simulated matches, not with --adaptive (it runs in this"
                         " process)"),
    (["--resume"], "--resume applies to the sweeps on simulated matches, not with --adaptive (it keeps no journal"),
    (["--env-kwargs", '{"noise_sigma": 1.0}'], "--env-kwargs {\"noise_sigma\": 1.0} applies to the sweeps"),
    (["--auc", "0.9"], "--auc 0.9 applies to the sweeps on simulated matches, not with --adaptive"),
    (["--agent", "consistency"], "--agent consistency applies to the sweeps on simulated matches and --source rendered,"
                                 " not with --adaptive (its learned sampler is --adaptive-sampler"),
    (["--format", "pdf"], "--format pdf applies to the sweeps on simulated matches and --source rendered, not with"
                          " --adaptive (its figures are PNG)"),
    (["--env-id", "vo_gym/StereoVOHard-v0"], "--env-id vo_gym/StereoVOHard-v0 applies to the sweeps"),
])
def test_an_option_the_adaptive_comparison_would_ignore_is_refused(tmp_path, capsys, more, needle):
    assert main(["evaluate", *ADAPTIVE, *more, "--out", str(tmp_path / "e")]) == 2
    assert needle in one_line_error(capsys, "evaluate")
    assert not (tmp_path / "e").exists()


@pytest.mark.parametrize("more, needle", [
    (["--adaptive-sampler", "adaptive-pg"], "--adaptive-sampler adaptive-pg applies to --adaptive, not to the sweeps on"
                                            " simulated matches"),
    (["--resolution", "vga"], "--resolution vga applies to --source rendered, not to the sweeps on simulated matches"),
    (["--source", "rendered", "--resume"], "--resume applies to the sweeps on simulated matches, not with --source"
                                           " rendered (it keeps no journal to resume from; --overwrite replaces the run)"),
    (["--source", "rendered", "--n", "100"], "--n 100 applies to the sweeps on simulated matches and --adaptive, not with"
                                             " --source rendered (the matches and their contamination are the image"),
    (["--source", "rendered", "--workers", "2"], "--workers 2 applies to the sweeps on simulated matches, not with"
                                                 " --source rendered"),
    (["--source", "rendered", "--adaptive-agents"], "--adaptive-agents applies to the sweeps on simulated matches"),
])
def test_an_option_of_another_run_is_refused_not_ignored(tmp_path, capsys, more, needle):
    assert main(["evaluate", *more, "--out", str(tmp_path / "e")]) == 2
    assert needle in one_line_error(capsys, "evaluate")
    assert not (tmp_path / "e").exists()


# Each value is the option's default: typing it still asks for something the run would not do.
@pytest.mark.parametrize("more, needle", [
    ([*ADAPTIVE, "--budget", "16"], "--budget 16 applies to the sweeps on simulated matches, not with --adaptive"),
    ([*ADAPTIVE, "--epsilons", "0.3,0.5,0.7,0.8,0.9"], "--epsilons 0.3,0.5,0.7,0.8,0.9 applies to the sweeps on"
                                                      " simulated matches, not with --adaptive"),
    ([*ADAPTIVE, "--format", "png"], "--format png applies to the sweeps on simulated matches and --source rendered,"
                                     " not with --adaptive (its figures are PNG)"),
    ([*ADAPTIVE, "--backend", "local"], "--backend local applies to the sweeps on simulated matches, not with"
                                        " --adaptive (it runs in this process)"),
    ([*ADAPTIVE, "--sweep-eps=0.8"], "--sweep-eps 0.8 applies to the sweeps on simulated matches, not with --adaptive"),
    (["--source", "rendered", "--n", "500"], "--n 500 applies to the sweeps on simulated matches and --adaptive, not"
                                             " with --source rendered"),
])
def test_an_option_typed_at_its_default_is_refused_where_the_run_does_not_read_it(tmp_path, capsys, more, needle):
    assert main(["evaluate", *more, "--out", str(tmp_path / "e")]) == 2
    assert needle in one_line_error(capsys, "evaluate")
    assert not (tmp_path / "e").exists()


def _tiny_comparison(config, log=print):
    """A stand-in for agents.evaluation.in_frame.run_comparison: one row, one progress line."""
    row = {"family": "learned (own stop)", "point": 0.9, "order": 0, "frames": 2, "success": 1.0, "successes": 2,
           "mean_hypotheses": 4.0, "stopped": 0, "miss_rate": None, "success_ci95": [0.34, 1.0]}
    log("standard eps 0.9: learned (own stop) 0.9: 1.000 at 4.0 (0 s)")
    return {"config": {"learned": config.learned, "seed": config.seed}, "standard eps 0.9": [row]}


def test_the_adaptive_comparison_honours_no_plots_no_progress_and_its_sampler(tmp_path, capsys, monkeypatch):
    import agents.evaluation.in_frame as in_frame

    monkeypatch.setattr(in_frame, "run_comparison", _tiny_comparison)
    assert main(["evaluate", *ADAPTIVE, "--out", str(tmp_path / "plots")]) == 0
    assert "learned (own stop) 0.9: 1.000" in capsys.readouterr().out
    assert (tmp_path / "plots" / "adaptive-standard-eps-0.9.png").stat().st_size > 0
    argv = ["evaluate", *ADAPTIVE, "--no-plots", "--no-progress", "--adaptive-sampler", "adaptive-pg"]
    assert main([*argv, "--out", str(tmp_path / "bare")]) == 0
    out = capsys.readouterr().out
    assert "1.000 at 4.0 (0 s)" not in out and "| learned (own stop) | 0.9 | 100.0 % |" in out
    assert sorted(p.name for p in (tmp_path / "bare").iterdir()) == ["adaptive.json", "adaptive.md"]
    assert json.loads((tmp_path / "bare" / "adaptive.json").read_text())["config"]["learned"] == "adaptive-pg"
    assert (tmp_path / "bare" / "adaptive.md").read_text() == (tmp_path / "plots" / "adaptive.md").read_text()
    # a second run into the same folder: --overwrite only (the comparison keeps no journal)
    assert main([*argv, "--out", str(tmp_path / "bare")]) == 2
    assert "is not empty; pass --overwrite to replace the run there" in one_line_error(capsys, "evaluate")
    assert main([*argv, "--overwrite", "--out", str(tmp_path / "bare")]) == 0


RENDERED = ["evaluate", "--source", "rendered", "--resolution", "vga", "--episodes", "1", "--frames-per-episode", "1",
            "--budgets", "2", "--agent", "uniform", "--seed", "4", "--no-progress", "--no-plots"]


def test_evaluate_on_rendered_images_keeps_a_non_empty_out_unless_overwrite(tmp_path, capsys):
    out = tmp_path / "kept"
    out.mkdir()
    (out / "notes.txt").write_text("an earlier run")
    assert main([*RENDERED, "--out", str(out)]) == 2
    assert f"--out '{out}' is not empty; pass --overwrite to replace the run there" in one_line_error(capsys, "evaluate")
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt"]
    assert main([*RENDERED, "--overwrite", "--out", str(out)]) == 0
    assert (out / "frames.csv").is_file()


def test_evaluate_on_rendered_images_takes_methods_none(tmp_path, capsys, short):
    assert main([*RENDERED, "--methods", "none", "--out", str(tmp_path / "e")]) == 0
    assert "1 agent(s) (uniform) and 0 classical method(s) (none)" in capsys.readouterr().out
    with (tmp_path / "e" / "frames.csv").open() as fh:
        assert {row["agent"] for row in csv.DictReader(fh)} == {"uniform"}
    assert main([*RENDERED, "--methods", "None,msac", "--out", str(tmp_path / "m")]) == 0
    with (tmp_path / "m" / "frames.csv").open() as fh:
        assert {row["agent"] for row in csv.DictReader(fh)} == {"uniform", "msac (fixed)"}


def test_evaluate_on_rendered_images_with_json_prints_one_json_document(tmp_path, capsys, short):
    assert main([*RENDERED, "--methods", "none", "--json", "--out", str(tmp_path / "j")]) == 0
    document = json.loads(capsys.readouterr().out)  # the header line used to come first
    assert document["settings"]["env_id"] == "vo_gym/StereoVOImages-v0"
    assert [row["agent"] for row in document["rows"]] == ["uniform"]


def test_adaptive_and_source_are_refused_together_as_two_runs(tmp_path, capsys):
    assert main(["evaluate", *ADAPTIVE, "--source", "rendered", "--out", str(tmp_path / "e")]) == 2
    line = one_line_error(capsys, "evaluate")
    assert line.startswith("vo-gym evaluate: error: --adaptive and --source rendered exclude each other"), line
    assert not (tmp_path / "e").exists()


def test_resume_with_a_trial_that_is_no_unit_of_the_run_is_one_line(tmp_path, capsys):
    # a renumbered unit used to be taken as done while its unit ran again under the "resuming" count
    out = tmp_path / "e"
    assert main(["evaluate", *SWEEP, "--out", str(out)]) == 0
    journal = out / "journal.csv"
    lines = journal.read_text().splitlines(keepends=True)
    lines[1] = "99" + lines[1][lines[1].index(","):]
    journal.write_text("".join(lines))
    capsys.readouterr()
    assert main(["evaluate", *SWEEP, "--out", str(out), "--resume"]) == 2
    assert "line 2: task 99 is not a task of this run" in one_line_error(capsys, "evaluate")


def test_options_left_out_or_read_by_the_run_are_not_refused(tmp_path, capsys, monkeypatch):
    import agents.evaluation.in_frame as in_frame

    monkeypatch.setattr(in_frame, "run_comparison", _tiny_comparison)
    # --n is read by --adaptive and --seed by every run, here at their defaults; the sweeps' options are left out
    assert main(["evaluate", *ADAPTIVE, "--n", "500", "--seed", "1000", "--no-plots", "--out", str(tmp_path / "a")]) == 0
    assert "| learned (own stop) | 0.9 | 100.0 % |" in capsys.readouterr().out


def test_arguments_parsed_without_main_count_an_option_as_given_when_it_is_not_at_its_default():
    from vo_gym_cli.commands import evaluate
    from vo_gym_cli.commands.common import UsageError
    from vo_gym_cli.main import build_parser

    parser = build_parser(["evaluate"])
    # no record of what was typed: an option at its default cannot be told from one left out
    evaluate.check_options_apply(parser.parse_args(["evaluate", "--adaptive", "--budget", "16"]))
    with pytest.raises(UsageError, match=r"^--budget 8 applies to the sweeps on simulated matches, not with --adaptive"):
        evaluate.check_options_apply(parser.parse_args(["evaluate", "--adaptive", "--budget", "8"]))


@pytest.mark.parametrize("refusal, message", [
    # a refusal whose words do not name the field still names the flag that set it
    (("episodes", " exceed the seeds left", "the episode count"), "--episodes exceed the seeds left"),
    (("methods", "none of these runs on simulated matches", ""), "--methods: none of these runs on simulated matches"),
])
def test_a_config_refusal_names_the_flag_of_its_field_not_of_its_words(tmp_path, capsys, monkeypatch, refusal, message):
    from agents.evaluation.setup import EvalConfig
    from vo_gym.settings import FieldError

    def refuse(self):
        raise FieldError(*refusal)

    monkeypatch.setattr(EvalConfig, "__post_init__", refuse)
    assert main(["evaluate", *SWEEP, "--out", str(tmp_path / "e")]) == 2
    assert one_line_error(capsys, "evaluate") == f"vo-gym evaluate: error: {message}"
    assert not (tmp_path / "e").exists()


def test_a_config_refusal_without_a_field_keeps_its_words_even_when_they_start_with_a_fields_name(tmp_path, capsys,
                                                                                                   monkeypatch):
    from agents.evaluation.setup import EvalConfig

    def refuse(self):
        raise ValueError("episodes must be fewer")  # no FieldError: which flag set it is not read from the words

    monkeypatch.setattr(EvalConfig, "__post_init__", refuse)
    assert main(["evaluate", *SWEEP, "--out", str(tmp_path / "e")]) == 2
    assert one_line_error(capsys, "evaluate") == "vo-gym evaluate: error: episodes must be fewer"
