"""A first run of the command line: missing extras are one line, a failed start writes nothing,
a run repeats with ``--overwrite``, and names typed slightly wrong get a "did you mean"."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import pytest

import vo_gym
from vo_gym_cli.main import main

ROOT = Path(__file__).resolve().parents[1]
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
    (["--auc", "1.5"], "error: --auc 1.5: "),
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
    with pytest.raises(ValueError, match=r"'max_hypothesis' \(did you mean 'max_hypotheses'\?\)"):
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
