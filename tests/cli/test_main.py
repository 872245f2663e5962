"""The command line's entry point (vo_gym_cli.main): every bad argument or unusable path is one line
naming it, exit 2, no traceback, checked before any computing; Ctrl-C is one line and exit 130;
--version and help with defaults; a first run (missing extras, failed starts, --overwrite, "did you
mean"); argument parsing under fuzzing."""

from __future__ import annotations

import argparse
import contextlib
import io
import shutil
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import pytest
from hypothesis import given, strategies as st

import vo_gym
from tests.support.cli import exit_code, one_line_error
from tests.support.fuzz import FUZZ
from vo_gym_cli import main as cli
from vo_gym_cli.main import main


ROOT = Path(__file__).resolve().parents[2]


TINY = ["--episodes", "1", "--frames-per-episode", "2", "--n", "80", "--epsilons", "0.5", "--budget", "4",
        "--budgets", "4", "--sweep-epsilon", "0.5", "--methods", "msac", "--no-plots", "--no-progress",
        "--workers", "1"]

# Runs the console script with the named top-level modules unimportable, as on an install without
# that extra (a meta-path finder refuses them; the rest of the environment is untouched).
BLOCKED_RUN = """
import sys
BLOCKED = set(sys.argv[1].split(","))
class Block:
    def find_spec(self, name, path=None, target=None):
        if name.partition(".")[0] in BLOCKED:
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
sys.meta_path.insert(0, Block())
from vo_gym_cli.main import main
code = main(sys.argv[2:])
print("loaded:", sorted(m for m in BLOCKED if m in sys.modules))
sys.exit(code)
"""


def _blocked(blocked: str, *argv: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", BLOCKED_RUN, blocked, *argv], capture_output=True, text=True,
                          cwd=cwd, timeout=600, env={**__import__("os").environ, "PYTHONPATH": str(ROOT)})


def _square(x):
    return [{"x": x * x}]


OPTION_TEXTS = st.sampled_from(["-1", "0", "1", "2", "0.5", "1e3", "nan", "inf", "-inf", "abc", "", "1,2", "a,b",
                                "0.3:0.9", "2:1", "1e309", "ppo", "msac", "/dev/null", "--x", " ", "0x10"])


BIG = "1" + "0" * 30
BAD_ARGUMENTS = [
    ("bench", ["--no-peers", "--frames", "0"], "--frames must be >= 1"),
    ("bench", ["--no-peers", "--frames", "x"], "--frames"),
    ("bench", ["--no-peers", "--ns", "a,b"], "--ns 'a' is not an integer"),
    ("bench", ["--no-peers", "--method", "nope"], "unknown method 'nope'"),
    ("bench", ["--no-peers", "--ns", "-1"], "--ns must be >= 3"),
    ("bench", ["--no-peers", "--ns", "2"], "--ns must be >= 3"),
    ("bench", ["--no-peers", "--epsilons", "2"], "--epsilons must be < 1.0"),
    ("bench", ["--no-peers", "--noise", "-1"], "--noise must be >= 0.001"),
    ("bench", ["--no-peers", "--seed", "-1"], "--seed must be >= 0"),
    ("vo", ["--outliers", "1.5"], "outlier ratio 1.5"),
    ("vo", ["--outliers", "0.9:0.3"], "lo <= hi"),
    ("vo", ["--outliers", "half"], "not a number"),
    ("vo", ["--frames", "0"], "--frames must be >= 1"),
    ("vo", ["--method", "nonsense"], "invalid choice: 'nonsense'"),
    ("vo", ["--preset", "boat"], "invalid choice: 'boat'"),
    ("vo", ["--seed", "-1"], "--seed"),
    ("vo", ["--noise", "nan"], "--noise"),
    ("vo", ["--n", "2"], "--n"),
    ("vo", ["--auc", "inf"], "--auc"),
    ("baselines", ["--epsilons", "0.2,1.5"], "error: --epsilons must be in [0, 1)"),
    ("baselines", ["--sigmas", "-1"], "error: --sigmas must be > 0 px"),
    ("baselines", ["--aucs", "1.2"], "error: --aucs must be a finite number in [0.5, 1), got 1.2"),
    ("baselines", ["--ns", "2"], "error: --ns must be an integer >= 3"),
    ("baselines", ["--outlier-kinds", "ghosts"], "error: --outlier-kinds: unknown outlier kind"),
    ("baselines", ["--workers", "0"], "--workers must be >= 1"),
    ("baselines", ["--seed", "-1"], "--seed must be >= 0"),
    ("baselines", ["--ns", "a,b"], "--ns"),
    ("baselines", ["--ns", "200,500,200"], "--ns '200,500,200' gives 200 twice"),
    ("bench", ["--ns", "200,200"], "--ns '200,200' gives 200 twice"),
    ("bench", ["--epsilons", "0.5,0.50"], "--epsilons '0.5,0.50' gives 0.50 twice"),
    ("evaluate", ["--methods", "ransac,msac,ransac"], "--methods 'ransac,msac,ransac' gives ransac twice"),
    ("train", ["--seed", "-1"], "--seed"),
    ("train", ["--epsilon", "2"], "--epsilon"),
    ("train", ["--gamma", "1.5"], "--gamma"),
    ("train", ["--n-envs", "0"], "--n-envs"),
    ("train", ["--timesteps", "1e3"], "--timesteps"),
    ("train", ["--lr", "-1"], "--lr"),
    # counts past the library's caps, refused while parsing: they overflowed a C int (bench --frames, --workers),
    # escaped as the simulator's traceback (bench --ns), were blamed on --env-id (evaluate) or failed every
    # estimator call of a run that then exited 0 (baselines --max-iterations)
    ("bench", ["--no-peers", "--ns", BIG], f"--ns must be <= 100000000, got {BIG}"),
    ("bench", ["--no-peers", "--frames", BIG], f"--frames must be <= 1000000, got {BIG}"),
    ("evaluate", ["--n", "2"], "--n must be >= 3, got 2"),
    ("evaluate", ["--frames-per-episode", BIG], f"--frames-per-episode must be <= 1000000, got {BIG}"),
    ("evaluate", ["--budget", BIG], f"--budget must be <= 1000000000, got {BIG}"),
    ("evaluate", ["--budgets", f"4,{BIG}"], f"--budgets must each be <= 1000000000, got {BIG}"),
    ("evaluate", ["--max-iterations", BIG], f"--max-iterations must be <= 1000000000, got {BIG}"),
    ("evaluate", ["--workers", BIG], f"--workers must be <= 1024, got {BIG}"),
    ("baselines", ["--max-iterations", BIG], f"--max-iterations must be <= 1000000000, got {BIG}"),
    ("baselines", ["--workers", "5000"], "--workers must be <= 1024, got 5000"),
    # seeds past what torch (64 bits) and stable-baselines3's numpy seeding (32 bits) take
    ("train", ["--seed", str(2**64)], f"--seed must be <= {2**64 - 1} with --algo ngransac, got {2**64}"),
    ("train", ["--algo", "ppo", "--seed", str(2**32)], f"--seed must be <= {2**32 - 1} with --algo ppo, got {2**32}"),
    # a typed value with a line break, or none at all, stays visible on the one line
    ("train", ["--resume", ""], "--resume: no checkpoint at ''"),
    ("train", ["--resume", "a\nb"], "--resume: no checkpoint at 'a\\nb'"),
    ("train", ["--algo", "ngransac", "--env-id", "a\nb"], "does not take --env-id a\\nb (an option of ppo)"),
    ("evaluate", ["--env-id", "a\nb"], "--env-id: environment 'a\\nb': "),
]
"""Bad values of every command: rejected while parsing (argparse's exit) or by the command's own
check (its return code), alike for the user: exit 2, one line naming the flag, nothing written."""


@pytest.mark.parametrize("command, argv, needle", BAD_ARGUMENTS)
def test_bad_arguments_are_one_line_naming_them(tmp_path, capsys, command, argv, needle):
    assert exit_code([command, *argv, "--out", str(tmp_path / "out"), "--no-progress"]) == 2
    assert needle in one_line_error(capsys, command)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("argv", [["vo"], ["bench", "--no-peers"], ["train"], ["evaluate"], ["baselines"],
                                  ["sweep", str(ROOT / "configs" / "sweeps" / "example.yaml")]])
def test_an_empty_out_is_refused_not_taken_for_the_current_folder(tmp_path, capsys, monkeypatch, argv):
    monkeypatch.chdir(tmp_path)
    assert exit_code([*argv, "--out", ""]) == 2
    assert one_line_error(capsys, argv[0]).endswith(
        "--out must name a file or folder, got '' (the current folder is '.')")
    assert not any(tmp_path.iterdir())  # vo wrote its results into the current folder


def test_bench_refuses_seeds_the_peers_cannot_take_before_computing(capsys):
    pytest.importorskip("cv2")
    assert exit_code(["bench", "--seed", str(2**31 - 1), "--frames", "2", "--ns", "60", "--epsilons", "0.5"]) == 2
    assert one_line_error(capsys, "bench").endswith(
        f"--seed {2**31 - 1} with --frames 2 seeds the peers up to {2**31}; they take seeds up to {2**31 - 1} "
        "(OpenCV's generator takes a C int): a smaller --seed, or --no-peers")


def test_train_unknown_env_id_is_a_usage_error(tmp_path, capsys):
    assert main(["train", "--algo", "ppo", "--env-id", "foo", "--out", str(tmp_path / "t")]) == 2
    line = one_line_error(capsys, "train")
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
    assert "--out" in one_line_error(capsys, command)


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


@pytest.mark.parametrize("argv, extra", [
    (["evaluate", "--agent", "ppo"], "train"),
    (["train", "--algo", "ngransac"], "train"),
    (["vo", "--agent", "ngransac-supervised", "--frames", "3"], "train"),
])
def test_a_command_that_needs_torch_says_which_extra_in_one_line(tmp_path, argv, extra):
    out = _blocked("torch,stable_baselines3,tensorboard", *argv, "--out", str(tmp_path / "out"), cwd=tmp_path)
    err = out.stderr.strip().splitlines()
    assert out.returncode == 2, out.stderr
    assert err == [f"vo-gym {argv[0]}: error: this needs the '{extra}' extra (torch is not installed):"
                   f" pip install 'vo-gym[{extra}]'"]
    assert not (tmp_path / "out").exists()


def test_sweep_without_the_distributed_extra_says_so(tmp_path):
    out = _blocked("yaml,ray", "sweep", str(ROOT / "configs" / "sweeps" / "example.yaml"), "--out",
                   str(tmp_path / "out"), cwd=tmp_path)
    assert out.returncode == 2
    assert out.stderr.strip() == ("vo-gym sweep: error: this needs the 'distributed' extra (yaml is not installed):"
                                  " pip install 'vo-gym[distributed]'")


def test_evaluate_of_heuristics_and_classical_methods_runs_without_torch(tmp_path):
    out = _blocked("torch,stable_baselines3,tensorboard", "evaluate", "--agent", "uniform", "--agent", "oracle",
                   *TINY, "--out", str(tmp_path / "out"), cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert out.stdout.rstrip().endswith("loaded: []")
    assert (tmp_path / "out" / "frames.csv").is_file() and "uniform" in (tmp_path / "out" / "summary.md").read_text()


@pytest.mark.parametrize("argv, needle", [
    (["--env-id", "vo_gym/StereoVO-v1"], "--env-id: environment 'vo_gym/StereoVO-v1'"),
    (["--env-id", "StereoVO-v0"], "did you mean 'vo_gym/StereoVO-v0'?"),
    (["--env-kwargs", '{"noise_sigmaa": 1.0}'], "'noise_sigmaa' (did you mean 'noise_sigma'?)"),
    (["--epsilons", "1.5"], "error: --epsilons must be distinct values in [0, 1), got (1.5,)"),
    (["--sweep-epsilon", "1"], "error: --sweep-epsilon must be in [0, 1), got 1.0"),
    (["--auc", "1.5"], "error: --auc must be a finite number in [0.5, 1), got 1.5"),
    (["--budgets", "0"], "error: --budgets must be an integer >= 1, got 0"),
    (["--agent", "nope"], "error: --agent: unknown agent 'nope'"),
    (["--methods", "nosac"], "error: --methods: unknown classical method(s): nosac"),
])
def test_a_failed_start_names_the_flag_and_leaves_out_as_it_was(tmp_path, capsys, argv, needle):
    fresh, kept = tmp_path / "fresh", tmp_path / "kept"
    kept.mkdir()
    (kept / "notes.txt").write_text("mine\n")
    for out, more in ((fresh, []), (kept, ["--overwrite"])):
        assert main(["evaluate", "--agent", "uniform", *TINY, *argv, *more, "--out", str(out)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and needle in err[0], err
    assert not fresh.exists()
    assert sorted(p.name for p in kept.iterdir()) == ["notes.txt"]


def test_a_start_that_fails_after_opening_the_folder_removes_what_it_wrote(tmp_path):
    # Ray is imported only when the backend starts, after --out was opened: that start must undo itself.
    for command in (["evaluate", "--agent", "uniform", *TINY],
                    ["baselines", "--frames-per-cell", "1", "--ns", "100", "--epsilons", "0.5", "--sigmas", "0.5",
                     "--aucs", "0.9", "--methods", "msac", "--no-progress", "--no-plots"]):
        out = _blocked("ray", *command, "--backend", "ray", "--out", str(tmp_path / "out"), cwd=tmp_path)
        assert out.returncode == 2, out.stderr
        assert out.stderr.strip().splitlines()[-1].endswith("pip install 'vo-gym[distributed]'"), out.stderr
        assert not (tmp_path / "out").exists()


def test_the_same_run_repeats_with_overwrite_and_gives_the_same_rows(tmp_path, capsys):
    out = tmp_path / "out"
    argv = ["evaluate", "--agent", "uniform", *TINY, "--out", str(out)]
    assert main(argv) == 0
    first = (out / "frames.csv").read_text()
    assert main(argv) == 2 and "is not empty" in capsys.readouterr().err
    assert main([*argv, "--overwrite"]) == 0
    strip = lambda text: [line.rsplit(",", 3)[0] for line in text.splitlines()]  # noqa: E731 - drops time columns
    assert strip((out / "frames.csv").read_text())[0] == strip(first)[0]
    assert len((out / "frames.csv").read_text().splitlines()) == len(first.splitlines())


def test_env_ids_hold_every_registered_id_and_bare_names_point_to_the_namespace():
    registered = sorted(i for i in gym.registry if i.startswith("vo_gym/"))
    assert list(vo_gym.ENV_IDS) == registered and len(registered) >= 6
    assert "vo_gym/StereoVOAdaptive-v0" in vo_gym.ENV_IDS
    with pytest.raises(gym.error.NamespaceNotFound, match=r"did you mean 'vo_gym/StereoVOHard-v0'\?"):
        gym.make("StereoVOHard-v0")


def test_a_near_miss_keyword_gets_a_did_you_mean():
    with pytest.raises(TypeError, match=r"'max_iteration' \(did you mean 'max_iterations'\?\)"):
        gym.make("vo_gym/StereoVO-v0", max_iteration=10)
    with pytest.raises(TypeError, match=r"'n_correspondence' \(did you mean 'n_correspondences'\?\)"):
        gym.make("vo_gym/StereoVO-v0", n_correspondence=10)
    with pytest.raises(TypeError, match=r"'max_hypothesis' \(did you mean 'max_hypotheses'\?\)"):
        gym.make("vo_gym/StereoVOAdaptive-v0", max_hypothesis=10)
    with pytest.raises(TypeError) as far:
        gym.make("vo_gym/StereoVO-v0", zzz=1)
    assert "did you mean" not in str(far.value)


def test_evaluate_help_lists_the_shipped_samplers(capsys):
    from agents.catalog import IN_FRAME_SAMPLERS, ONE_SHOT_SAMPLERS

    with pytest.raises(SystemExit):
        main(["evaluate", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert all(name in text for name in ONE_SHOT_SAMPLERS + IN_FRAME_SAMPLERS)


def test_a_users_checkpoint_with_a_shipped_name_is_labelled_by_its_path(tmp_path):
    from agents.evaluation.setup import resolve_agents

    mine = tmp_path / "ngransac-supervised.pt"
    shutil.copy(ROOT / "agents" / "checkpoints" / "ngransac-supervised.pt", mine)
    specs = resolve_agents(["ngransac-supervised", str(mine),
                            str(ROOT / "agents" / "checkpoints" / "ppo.pt")])
    assert [s.label for s in specs] == ["ngransac-supervised", str(mine), "ppo"]


def test_evaluate_figures_keep_agents_and_classical_apart_and_name_the_recipes(tmp_path, monkeypatch):
    import agents.evaluation.report as report

    saved = {}
    monkeypatch.setattr(report, "save_figure", lambda fig, path: saved.setdefault(path.name, fig) and path)
    argv = [a for a in TINY if a != "--no-plots"]
    argv[argv.index("--methods") + 1] = "ransac,msac"
    assert main(["evaluate", "--agent", "uniform", "--agent", "match-score", "--agent", "oracle", *argv,
                 "--out", str(tmp_path / "out")]) == 0
    colours: dict[str, set] = {}
    for name, fig in saved.items():
        for ax in fig.axes:
            labels = [t.get_text() for t in ax.get_legend().get_texts()] if ax.get_legend() else []
            series = [line for line in ax.get_lines() if not line.get_label().startswith(("_", "99 %"))]
            assert len(series) <= 8, (name, labels)
            kinds = {("classical" if "(" in line.get_label() and "upper bound" not in line.get_label() else "agent")
                     for line in series}
            assert len(kinds) <= 1, (name, [line.get_label() for line in series])  # never mixed in one panel
            for line in series:
                colours.setdefault(line.get_label(), set()).add(line.get_color())
        titles = " ".join(ax.get_title(loc="left") for ax in fig.axes) + fig.get_suptitle()
        assert "environment's recipe" in titles, name
    assert all(len(c) == 1 for c in colours.values()), colours  # one colour per row in every panel
    assert "textbook" in " ".join(ax.get_title(loc="left") for ax in saved["success_vs_epsilon.png"].axes)
    left, right = saved["success_vs_budget.png"].axes[0].get_xlim()
    assert 2 <= left < 4 and 4 < right <= 8  # the budget axis spans the budgets run (4), not the adaptive runs'


def test_baselines_repeats_with_overwrite_and_points_to_the_claims(tmp_path, capsys):
    argv = ["baselines", "--frames-per-cell", "1", "--ns", "100", "--epsilons", "0.5", "--sigmas", "0.5",
            "--aucs", "0.9", "--methods", "ransac,prosac", "--no-progress", "--no-plots", "--workers", "1",
            "--out", str(tmp_path / "out")]
    assert main(argv) == 0
    assert main([*argv, "--overwrite"]) == 0
    printed = capsys.readouterr().out
    assert printed.count(f"{tmp_path / 'out' / 'claims.md'} states each claim") == 2


def test_the_bar_says_compiling_instead_of_an_eta_until_the_first_trial(monkeypatch, capsys):
    from stereovo.trials import Task, make_backend, run_tasks
    from stereovo.trials import runner

    monkeypatch.setattr(runner, "announce_once_for_workers", lambda: True)  # as on a first run
    result = run_tasks(_square, [Task(i, i) for i in range(3)], make_backend("local", 1), desc="demo")
    assert {k: v[0]["x"] for k, v in result.results.items()} == {0: 0, 1: 1, 2: 4}
    err = capsys.readouterr().err
    first, _, rest = err.partition("demo: compiling the kernels (first run), ")
    assert _ and "<" not in err.split("compiling")[1].split("\n")[0]  # no remaining-time estimate there
    assert "3/3" in rest and "compiling" not in rest.rsplit("demo", 1)[1]  # a plain bar once compiled


def test_the_compile_notice_is_silent_in_workers_of_a_run_that_printed_it(monkeypatch, capsys):
    from stereovo import compilation

    compilation.reset_announcement()
    monkeypatch.setattr(compilation, "uncached_kernels", lambda kernels=None: ["k"])
    monkeypatch.setenv(compilation.QUIET_ENV, "1")  # what a worker inherits
    assert compilation.say_compiling() is False and compilation.announce_compiling([object()]) is False
    monkeypatch.delenv(compilation.QUIET_ENV)
    compilation.reset_announcement()
    assert compilation.announce_compiling([object()]) is True and compilation.say_compiling() is False
    assert capsys.readouterr().err.count(compilation.MESSAGE) == 1
    compilation.reset_announcement()


@pytest.mark.parametrize("command", list(cli.COMMANDS))
@FUZZ
@given(picks=st.lists(st.tuples(st.integers(0, 1000), OPTION_TEXTS), min_size=1, max_size=3))
def test_cli_argument_parsing_fuzz(command, picks):
    """Parsing alone (no command runs): either it parses, or one line naming an argument and exit 2."""
    parser = cli.build_parser([command])
    sub = next(a for a in parser._actions if a.dest == "command").choices[command]
    options = [a for a in sub._actions if a.option_strings and a.dest != "help"]
    argv = [command]
    for index, text in picks:
        action = options[index % len(options)]
        argv.append(action.option_strings[-1])
        if action.nargs != 0:
            argv.append(text)
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            parser.parse_args(argv)
        except SystemExit as exc:
            assert exc.code == 2, (argv, exc.code)
            lines = err.getvalue().strip().splitlines()
            assert len(lines) == 1 and lines[0].startswith(f"vo-gym {command}: error:"), (argv, lines)
            assert "--" in lines[0] or "argument" in lines[0], (argv, lines)
