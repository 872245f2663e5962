"""``vo-gym sweep``: sweep files are checked key by key (safe YAML only), and a tiny sweep of each
trainer runs on Ray Tune end to end, writes its table, plot, best config and checkpoint, and restores."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

from agents.sweep_config import load_sweep, parse_sweep
from vo_gym_cli.main import main

ROOT = Path(__file__).resolve().parents[2]

NGRANSAC = """
name: tiny
algo: ngransac
fixed: {frames: 6, n_correspondences: 60, pools: 2, eval_frames: 1}
space:
  seed: {grid: [0, 1]}
  learning_rate: {loguniform: [0.0001, 0.001]}
report_every: 3
metric: {epsilon: 0.5, budget: 8, n: 60, episodes: 1, frames_per_episode: 2}
scheduler: {type: fifo}
"""

PPO = """
name: tiny-ppo
algo: ppo
fixed: {timesteps: 32, n_envs: 1, n_steps: 16, batch_size: 16, n_epochs: 1, n_correspondences: 40, n_frames: 4,
        eval_n_correspondences: 60}
space:
  seed: {grid: [0]}
report_every: 16
metric: {epsilon: 0.5, budget: 8, n: 60, episodes: 1, frames_per_episode: 2}
"""


def _write(tmp_path: Path, text: str, name: str = "sweep.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.mark.parametrize("name", ["example.yaml", "realistic.yaml"])
def test_shipped_sweep_files_parse(name):
    spec = load_sweep(ROOT / "configs" / "sweeps" / name)
    assert spec.algo == "ngransac" and "seed" in spec.space and spec.scheduler["type"] == "asha"
    assert spec.n_reports == -(-spec.total_steps // spec.report_every)


@pytest.mark.parametrize(
    "change, needle",
    [
        ({"colour": 1}, "unknown key(s) ['colour']"),
        ({"algo": "dqn"}, "algo must be one of"),
        ({"space": {"seed": {"spiral": [1]}}}, "space.seed: unknown axis kind 'spiral'"),
        ({"space": {"learning_rate": {"uniform": [0.1, 0.01]}}}, "space.learning_rate.uniform must be [low, high]"),
        ({"space": {"wingspan": {"grid": [1, 2]}}}, "unknown NGRansacConfig field(s) ['wingspan']"),
        ({"metric": {"name": "reward"}}, "metric.name must be 'success'"),
        ({"metric": {"budget": 0}}, "metric.budget must be an integer >= 1"),
        ({"scheduler": {"type": "hyperband"}}, "scheduler.type must be 'asha' or 'fifo'"),
        ({"report_every": None}, "report_every must be an integer >= 1"),
        ({"fixed": {"seed": 3}}, "['seed'] both fixed and searched"),
    ],
)
def test_bad_sweep_files_name_the_key(change, needle):
    import yaml

    data = {**yaml.safe_load(NGRANSAC), **change}
    with pytest.raises(ValueError) as err:
        parse_sweep(data, "s.yaml")
    assert needle in str(err.value)


def test_yaml_that_would_build_objects_is_refused(tmp_path):
    path = _write(tmp_path, NGRANSAC + "\nextra: !!python/object/apply:os.system ['echo pwned']\n")
    with pytest.raises(ValueError, match="not valid YAML"):
        load_sweep(path)


def test_the_command_reports_a_bad_file_in_one_line(tmp_path, capsys):
    assert main(["sweep", str(_write(tmp_path, "algo: ngransac\n")), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("vo-gym sweep: error:") and "space" in err[0]
    assert main(["sweep", str(tmp_path / "missing.yaml")]) == 2


_BOMB = "".join(f"{c}: &{c} [{', '.join(['*' + p] * 9) if p else 'x, x, x, x, x, x, x, x, x'}]\n"
                for p, c in zip([None, *"abcdefgh"], "abcdefghi"))


@pytest.mark.parametrize("where", ["top", "fixed", "budget"])
def test_an_alias_bomb_is_refused_before_it_expands(tmp_path, where):
    if where == "top":
        text = NGRANSAC + _BOMB
    elif where == "fixed":
        text = NGRANSAC.replace("fixed: {frames: 6, n_correspondences: 60, pools: 2, eval_frames: 1}",
                                "fixed:\n" + "".join(f"  - {line}\n" for line in _BOMB.splitlines()))
    else:
        text = NGRANSAC.replace("metric: {epsilon: 0.5, budget: 8,", "metric: {epsilon: 0.5, budget: *i,") + _BOMB
    with pytest.raises(ValueError) as err:
        load_sweep(_write(tmp_path, text))
    message = str(err.value)
    assert "sweep.yaml: not valid YAML (line " in message and "anchors and aliases" in message
    assert "\n" not in message and len(message) < 300


def test_a_single_alias_is_refused_too(tmp_path):
    text = NGRANSAC.replace("report_every: 3", "report_every: &r 3\nsamples: *r")
    with pytest.raises(ValueError, match=r"sweep.yaml: not valid YAML \(line 8: anchors and aliases"):
        load_sweep(_write(tmp_path, text))


@pytest.mark.parametrize("deep", ["[" * 50000 + "]" * 50000, "{a: " * 50000 + "1" + "}" * 50000])
def test_deep_nesting_is_refused_in_one_line(tmp_path, deep):
    with pytest.raises(ValueError, match=r"sweep.yaml: not valid YAML \(line 11: nested more than 32 deep\)$"):
        load_sweep(_write(tmp_path, NGRANSAC + "extra: " + deep + "\n"))


@pytest.mark.parametrize("name", ["../../../../tmp/x", "a/b", "a\\b", "..", ".hidden", "", "x" * 5000, "a\tb"])
def test_the_name_is_one_folder_under_runs_sweep(tmp_path, name):
    import yaml

    with pytest.raises(ValueError) as err:
        parse_sweep({**yaml.safe_load(NGRANSAC), "name": name}, "s.yaml")
    message = str(err.value)
    assert message.startswith("s.yaml: name must be a single folder name") and len(message) < 400
    assert (repr(name) if len(name) < 100 else "'xxxx") in message


def test_a_name_that_escapes_runs_sweep_writes_nothing(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    config = _write(tmp_path, NGRANSAC.replace("name: tiny", "name: ../../escaped"))
    assert main(["sweep", str(config)]) == 2
    [line] = capsys.readouterr().err.strip().splitlines()
    assert line == (f"vo-gym sweep: error: {config}: name must be a single folder name of 1 to 100 characters"
                    " without '/', '\\', ':' or a leading '.', got '../../escaped'")
    assert not (tmp_path / "escaped").exists() and not (tmp_path / "runs").exists()


@pytest.mark.parametrize(
    "change, needle",
    [
        ({"fixed": {"frames": "many"}}, "s.yaml: fixed.frames must be an integer, got 'many'"),
        ({"fixed": {"learning_rate": [1, 2]}}, "s.yaml: fixed.learning_rate must be a finite number, got [1, 2]"),
        ({"fixed": {"frames": 6, "epsilon_range": "wide"}}, "s.yaml: fixed.epsilon_range must be a list of 2"),
        ({"space": {"seed": {"grid": [0, "one"]}}}, "s.yaml: space.seed.grid[1] must be an integer, got 'one'"),
        ({"space": {"seed": {"randint": [0, float("inf")]}}}, "space.seed.randint must be [low, high] finite"),
        ({"space": {"seed": {"randint": [0, 2.5]}}}, "space.seed.randint must be [low, high] integers"),
        ({"algo": "x" * 10000}, "s.yaml: algo must be one of ('ngransac', 'ppo'), got 'xxx"),
        ({"fixed": ["x"] * 100000}, "s.yaml: fixed must be a mapping, got ['x', "),
        ({"x" * 10000: 1, 3: 4}, "s.yaml: unknown key(s) ["),
        ({"scheduler": "fifo"}, "s.yaml: scheduler must be a mapping, got 'fifo'"),
        ({"scheduler": {"type": "asha", "reduction_factor": float("nan")}},
         "s.yaml: scheduler.reduction_factor must be a finite number > 1, got nan"),
        ({"samples": 0}, "s.yaml: samples must be an integer >= 1 and <= 1000, got 0"),
        ({"metric": {"budget": "x" * 10000}}, "s.yaml: sweep metric.budget"),
        ({"metric": {"env_id": [1]}}, "s.yaml: metric.env_id must be a string, got [1]"),
    ],
)
def test_bad_values_name_the_file_and_key_in_a_short_message(change, needle):
    import yaml

    data = {**yaml.safe_load(NGRANSAC), **change}
    with pytest.raises(ValueError) as err:
        parse_sweep(data, "s.yaml")
    assert needle in str(err.value) and len(str(err.value)) < 600


@pytest.mark.parametrize(
    "algo, fixed, needle",
    [
        ("ngransac", {"keep_best": "yes"}, "s.yaml: fixed.keep_best must be true or false, got 'yes'"),
        ("ngransac", {"keep_best": 1}, "s.yaml: fixed.keep_best must be true or false, got 1"),
        ("ngransac", {"loss": 3}, "s.yaml: fixed.loss must be a string, got 3"),
        ("ngransac", {"frames": True}, "s.yaml: fixed.frames must be an integer, got True"),
        ("ngransac", {"frames": None}, "s.yaml: fixed.frames must be an integer, got None"),
        ("ngransac", {"learning_rate": float("nan")}, "s.yaml: fixed.learning_rate must be a finite number, got nan"),
        ("ngransac", {"learning_rate": 10**400}, "s.yaml: fixed.learning_rate must be a finite number, got ~1e+400 (an integer of 401 digits)"),
        ("ngransac", {"max_grad_norm": "big"}, "s.yaml: fixed.max_grad_norm must be a finite number or null, got 'big'"),
        ("ngransac", {"outlier_mix": [0.5, 0.5]},
         "s.yaml: fixed.outlier_mix must be a list of 3 finite numbers, got [0.5, 0.5]"),
        ("ppo", {"env_kwargs": [1]}, "s.yaml: fixed.env_kwargs must be a mapping, got [1]"),
        ("ppo", {"critic_width": "wide"}, "s.yaml: fixed.critic_width must be an integer or null, got 'wide'"),
        ("ppo", {"share_trunk": "no"}, "s.yaml: fixed.share_trunk must be true or false, got 'no'"),
    ],
)
def test_each_kind_of_trainer_field_refuses_a_value_of_another_type(algo, fixed, needle):
    import yaml

    data = yaml.safe_load(NGRANSAC if algo == "ngransac" else PPO)
    with pytest.raises(ValueError) as err:
        parse_sweep({**data, "fixed": {**data["fixed"], **fixed}}, "s.yaml")
    assert str(err.value) == needle


def test_a_searched_optional_field_takes_null_and_names_the_bad_value_by_index():
    import yaml

    data = yaml.safe_load(NGRANSAC)
    spec = parse_sweep({**data, "space": {**data["space"], "max_grad_norm": {"choice": [1.0, None]}}}, "s.yaml")
    assert spec.space["max_grad_norm"] == {"choice": [1.0, None]}
    with pytest.raises(ValueError) as err:
        parse_sweep({**data, "space": {**data["space"], "max_grad_norm": {"choice": [1.0, None, "x"]}}}, "s.yaml")
    assert str(err.value) == "s.yaml: space.max_grad_norm.choice[2] must be a finite number or null, got 'x'"


def test_valid_values_of_each_kind_of_trainer_field_are_accepted():
    import yaml

    data = yaml.safe_load(NGRANSAC)
    spec = parse_sweep({**data, "fixed": {**data["fixed"], "max_grad_norm": None, "outlier_mix": [0.5, 0.3, 0.2],
                                          "keep_best": True, "loss": "supervised"}}, "s.yaml")
    config = spec.trainer_config({"seed": 0, "learning_rate": 1e-4})
    assert config.max_grad_norm is None and config.outlier_mix == (0.5, 0.3, 0.2) and config.keep_best is True
    data = yaml.safe_load(PPO)
    spec = parse_sweep({**data, "fixed": {**data["fixed"], "critic_width": None, "env_kwargs": {}}}, "s.yaml")
    config = spec.trainer_config({"seed": 0})
    assert config.critic_width is None and config.env_kwargs == {} and config.timesteps == 32


def test_a_field_type_is_checked_by_what_it_is_not_how_it_is_spelled():
    import typing
    from typing import Any

    from agents.sweep_config import field_rule

    values = [0, 1.5, float("nan"), True, None, "x", [0.1, 0.2], {"a": 1}]

    def verdict(rule):
        """The rule in words and which of ``values`` it lets through."""
        passed = []
        for value in values:
            try:
                rule.check("s.yaml", "f", value)
                passed.append(value)
            except ValueError:
                pass
        return rule.rule, rule.optional, repr(passed)

    spellings = [
        [float | None, typing.Optional[float], typing.Union[None, float]],
        [tuple[float, float], typing.Tuple[float, float]],
        [dict[str, Any], typing.Dict[str, Any], typing.Mapping[str, Any], dict],
    ]
    for group in spellings:
        assert len({verdict(field_rule(t)) for t in group}) == 1, group
    assert verdict(field_rule(float | None)) == ("a finite number", True, "[0, 1.5, None]")
    assert field_rule(int | None).optional and not field_rule(int).optional
    assert field_rule(Any) is None  # not checked: the trainer's config class checks it
    for unknown in ("int", list[int], int | str, Path):
        with pytest.raises(TypeError, match="no check for a trainer config field of type"):
            field_rule(unknown)


@pytest.mark.parametrize("samples", [1001, 10**12, 2.5, True])
def test_samples_past_the_bound_are_refused_naming_the_field_and_value(samples):
    import yaml

    with pytest.raises(ValueError) as err:
        parse_sweep({**yaml.safe_load(NGRANSAC), "samples": samples}, "s.yaml")
    assert str(err.value) == f"s.yaml: samples must be an integer >= 1 and <= 1000, got {samples!r}"


def test_samples_up_to_the_bound_are_accepted():
    import yaml

    from agents.sweep_config import MAX_SAMPLES

    assert MAX_SAMPLES == 1000  # the bound the module doc and the messages state
    for samples in (1, MAX_SAMPLES):
        assert parse_sweep({**yaml.safe_load(NGRANSAC), "samples": samples}, "s.yaml").samples == samples
    assert parse_sweep(yaml.safe_load(NGRANSAC), "s.yaml").samples == 1  # the default


@pytest.mark.parametrize("key, value, rule", [
    ("episodes", 10**12, ">= 1 and <= 10000"),
    ("frames_per_episode", 10**7, ">= 1 and <= 1000000"),
    ("n", 2, ">= 3 and <= 100000000"),
    ("budget", 10**10, ">= 1 and <= 1000000000"),
])
def test_metric_counts_past_what_the_environment_takes_are_refused_before_any_trial(key, value, rule):
    """A typo in the metric would otherwise start the sweep and fail, or never end, in every trial."""
    import yaml

    data = yaml.safe_load(NGRANSAC)
    data["metric"] = {**data.get("metric", {}), key: value}
    with pytest.raises(ValueError, match=rf"sweep metric.{key} must be an integer {rule}, got {value}$"):
        parse_sweep(data, "s.yaml")
    data["metric"][key] = {"episodes": 10_000, "frames_per_episode": 10**6, "n": 3, "budget": 10**9}[key]
    assert getattr(parse_sweep(data, "s.yaml").metric, key) == data["metric"][key]


def test_a_file_that_is_not_utf8_a_directory_or_too_large_is_named(tmp_path):
    latin = tmp_path / "latin.yaml"
    latin.write_bytes(NGRANSAC.replace("tiny", "caf\xe9").encode("latin-1"))
    with pytest.raises(ValueError, match=r"latin.yaml: not UTF-8 text \(byte 10: b'\\xe9'\)"):
        load_sweep(latin)
    folder = tmp_path / "folder.yaml"
    folder.mkdir()
    with pytest.raises(ValueError, match=r"folder.yaml: is a directory, not a sweep file"):
        load_sweep(folder)
    with pytest.raises(ValueError, match=r"big.yaml: larger than 1024 KiB"):
        load_sweep(_write(tmp_path, NGRANSAC + "#" * (1 << 20), "big.yaml"))


def test_the_command_refuses_each_defect_in_one_line(tmp_path, capsys):
    cases = {
        "bomb.yaml": NGRANSAC + _BOMB,
        "deep.yaml": NGRANSAC + "extra: " + "[" * 50000 + "]" * 50000 + "\n",
        "frames.yaml": NGRANSAC.replace("frames: 6", "frames: many"),
        "tag.yaml": NGRANSAC + "extra: !!python/object/apply:os.system ['echo pwned']\n",
    }
    for name, text in cases.items():
        assert main(["sweep", str(_write(tmp_path, text, name)), "--out", str(tmp_path / "o")]) == 2
        [line] = capsys.readouterr().err.strip().splitlines()
        assert line.startswith(f"vo-gym sweep: error: {tmp_path / name}: ") and len(line) < 400, line
    assert not (tmp_path / "o").exists()
    assert main(["sweep", str(tmp_path)]) == 2
    assert capsys.readouterr().err.strip() == f"vo-gym sweep: error: {tmp_path}: is a directory, not a sweep file"


def _results(out: Path) -> list[dict[str, str]]:
    with (out / "results.csv").open(newline="") as fh:
        return list(csv.DictReader(fh))


def test_a_tiny_ngransac_sweep_runs_writes_its_outputs_and_restores(tmp_path, capsys):
    pytest.importorskip("ray")
    from agents.checkpoint import load_checkpoint

    config, out = _write(tmp_path, NGRANSAC), tmp_path / "out"
    assert main(["sweep", str(config), "--out", str(out), "--workers", "2", "--quiet"]) == 0
    rows = _results(out)
    assert len(rows) == 2 and {r["seed"] for r in rows} == {"0", "1"}
    assert all(r["reports"] == "2" and r["steps"] == "6" and r["status"] == "finished" for r in rows)
    best = json.loads((out / "best.json").read_text())
    assert best["config"]["frames"] == 6 and best["params"]["seed"] in (0, 1)
    assert 1e-4 <= best["params"]["learning_rate"] <= 1e-3 and best["config"]["n_correspondences"] == 60
    assert best["success"] == max(float(r["best_success"]) for r in rows)
    net, payload = load_checkpoint(out / "best_checkpoint" / "ngransac.pt")
    assert payload["config"]["seed"] == best["params"]["seed"]
    assert (out / "metric_over_training.png").stat().st_size > 0
    assert "Sweep tiny (ngransac)" in (out / "results.md").read_text()

    capsys.readouterr()
    assert main(["sweep", str(config), "--out", str(out), "--quiet"]) == 2  # not empty
    assert "--resume" in capsys.readouterr().err
    (out / "results.csv").unlink()
    assert main(["sweep", str(config), "--out", str(out), "--workers", "2", "--quiet", "--resume"]) == 0
    assert _results(out) == rows  # restored from Tune's saved experiment, nothing re-run


def test_a_tiny_ppo_sweep_runs_with_a_quiet_console(tmp_path, capfd):
    pytest.importorskip("ray")
    out = tmp_path / "out"
    assert main(["sweep", str(_write(tmp_path, PPO)), "--out", str(out), "--workers", "1"]) == 0
    # without --verbose: one progress bar and the summary, none of Ray's or Tune's coloured console
    printed = "".join(capfd.readouterr())
    assert "\x1b[" not in printed and "Trial status" not in printed and "\u256d" not in printed, printed[-2000:]
    [row] = _results(out)
    assert row["reports"] == "2" and row["steps"] == "32"
    assert (out / "best_checkpoint" / "ppo.zip").is_file() and (out / "best_checkpoint" / "ppo.pt").is_file()


STEP_IDS = "vo_gym/StereoVO-v0, vo_gym/StereoVOHard-v0, vo_gym/StereoVOProsac-v0, vo_gym/StereoVOProsacHard-v0"


@pytest.mark.parametrize("algo, change, message", [
    ("ngransac", {"metric": {"env_id": "nosuch"}},
     f"s.yaml: metric.env_id 'nosuch' is not a registered environment; the metric steps a one-shot policy through"
     f" one of: {STEP_IDS}"),
    ("ngransac", {"metric": {"env_id": "vo_gym/StereoVOAdaptive-v0"}},
     "s.yaml: metric.env_id 'vo_gym/StereoVOAdaptive-v0' is an in-frame environment (its action also stops the"
     f" search); the metric steps a one-shot policy through one of: {STEP_IDS}"),
    ("ngransac", {"metric": {"env_id": "vo_gym/StereoVOImages-v0"}},
     "s.yaml: metric.env_id 'vo_gym/StereoVOImages-v0' is an image environment; the metric steps a one-shot policy"
     f" through one of: {STEP_IDS}"),
    ("ngransac", {"metric": {"env_id": "StereoVO-v0"}},
     "s.yaml: metric.env_id 'StereoVO-v0' is not a vo_gym step environment (did you mean 'vo_gym/StereoVO-v0'?);"
     f" the metric steps a one-shot policy through one of: {STEP_IDS}"),
    ("ppo", {"space": {"env_id": {"choice": ["vo_gym/StereoVO-v0", "vo_gym/StereoVOAdaptiveHard-v0"]}}},
     "s.yaml: space.env_id.choice[1] 'vo_gym/StereoVOAdaptiveHard-v0' is an in-frame environment (its action also"
     f" stops the search); PPO trains in one of: {STEP_IDS}"),
])
def test_an_environment_the_sweep_cannot_step_is_refused_naming_the_file_and_key(algo, change, message):
    import yaml

    data = yaml.safe_load(NGRANSAC if algo == "ngransac" else PPO)
    with pytest.raises(ValueError) as err:
        parse_sweep({**data, **change}, "s.yaml")
    assert str(err.value) == message
    fine = {"metric": {"env_id": "vo_gym/StereoVOProsacHard-v0"}}  # a step id, of the PROSAC kind: fine
    assert parse_sweep({**data, **fine}, "s.yaml").metric.env_id == "vo_gym/StereoVOProsacHard-v0"


@pytest.mark.parametrize("algo, change, message", [
    ("ngransac", {"fixed": {"frames": 10**400}},
     "s.yaml: fixed.frames must be an integer >= 1 and <= 1000000000, got ~1e+400 (an integer of 401 digits)"),
    ("ngransac", {"report_every": 10**400},
     "s.yaml: report_every must be an integer >= 1 and <= 1000000000, got ~1e+400 (an integer of 401 digits)"),
    ("ngransac", {"space": {"seed": {"grid": [0]}, "eval_every": {"grid": [10**10]}}},
     "s.yaml: space.eval_every (its first value) must be an integer >= 1 and <= 1000000000, got 10000000000"),
    ("ppo", {"fixed": {"timesteps": 10**400, "n_envs": 1, "n_steps": 16, "batch_size": 16}},
     "s.yaml: fixed.timesteps must be an integer >= 1 and <= 1000000000, got ~1e+400 (an integer of 401 digits)"),
])
def test_counts_past_the_trainers_caps_are_refused_before_any_trial(algo, change, message):
    import yaml

    data = yaml.safe_load(NGRANSAC if algo == "ngransac" else PPO)
    with pytest.raises(ValueError) as err:
        parse_sweep({**data, **change}, "s.yaml")
    assert str(err.value) == message


def test_the_largest_counts_give_their_number_of_reports_exactly():
    import yaml

    data = yaml.safe_load(NGRANSAC)
    spec = parse_sweep({**data, "fixed": {**data["fixed"], "frames": 10**9}, "report_every": 3}, "s.yaml")
    assert spec.n_reports == 333_333_334  # ceil(10**9 / 3), in integers


def test_a_huge_count_in_a_sweep_file_is_refused_before_out_is_made(tmp_path, capsys, monkeypatch):
    import agents.sweep

    def started(*args, **kwargs):
        raise AssertionError("the sweep started: its file should have been refused")

    monkeypatch.setattr(agents.sweep, "run_sweep", started)
    config = _write(tmp_path, NGRANSAC.replace("frames: 6", "frames: 1" + "0" * 400))
    assert main(["sweep", str(config), "--out", str(tmp_path / "out")]) == 2
    [line] = capsys.readouterr().err.strip().splitlines()
    assert line == (f"vo-gym sweep: error: {config}: fixed.frames must be an integer >= 1 and <= 1000000000,"
                    " got ~1e+400 (an integer of 401 digits)")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("text, message", [
    ("fixed: {frames: 6, n_correspondences: 60, pools: 2, eval_frames: 1, learning_rate: 1e-4}",
     "fixed.learning_rate must be a finite number, got '1e-4' (YAML reads '1e-4' as text; write 1.0e-4: a YAML"
     " float needs a dot and a signed exponent)"),
    ("fixed: {frames: 6, n_correspondences: 60, pools: 2, eval_frames: 1, entropy_weight: 2E3}",
     "fixed.entropy_weight must be a finite number, got '2E3' (YAML reads '2E3' as text; write 2.0e+3: a YAML"
     " float needs a dot and a signed exponent)"),
    ("fixed: {frames: 6, n_correspondences: 60, pools: 2, eval_frames: 1, learning_rate: '0.001'}",
     "fixed.learning_rate must be a finite number, got '0.001' (YAML reads '0.001' as text; write 0.001, without"
     " quotes)"),
    ("fixed: {frames: 1e3, n_correspondences: 60, pools: 2, eval_frames: 1}",
     "fixed.frames must be an integer, got '1e3' (YAML reads '1e3' as text; write 1000)"),
])
def test_a_number_yaml_reads_as_text_is_refused_with_how_to_write_it(tmp_path, text, message):
    path = _write(tmp_path, NGRANSAC.replace("fixed: {frames: 6, n_correspondences: 60, pools: 2, eval_frames: 1}", text))
    with pytest.raises(ValueError) as err:
        load_sweep(path)
    assert str(err.value) == f"{path}: {message}"
    written = _write(tmp_path, NGRANSAC.replace("pools: 2,", "pools: 2, entropy_weight: 1.0e-4,"), "fixed.yaml")
    assert load_sweep(written).fixed["entropy_weight"] == 1e-4  # as the message says to write it


def test_numbers_yaml_reads_as_text_are_named_in_the_metric_the_axes_and_the_scheduler():
    import yaml

    data = yaml.safe_load(NGRANSAC)
    for change, needle in [
        ({"metric": {"epsilon": "5e-1"}}, "sweep metric.epsilon must be a finite number in [0, 1), got '5e-1'"
                                          " (YAML reads '5e-1' as text; write 5.0e-1"),
        ({"space": {"learning_rate": {"loguniform": ["1e-5", 0.001]}}}, "got ['1e-5', 0.001] (YAML reads '1e-5' as"
                                                                        " text; write 1.0e-5"),
        ({"scheduler": {"type": "asha", "reduction_factor": "3e0"}}, "got '3e0' (YAML reads '3e0' as text; write 3.0e+0"),
        ({"samples": "1e2"}, "s.yaml: samples must be an integer >= 1 and <= 1000, got '1e2' (YAML reads '1e2' as"
                             " text; write 100)"),
    ]:
        with pytest.raises(ValueError) as err:
            parse_sweep({**data, **change}, "s.yaml")
        assert needle in str(err.value), str(err.value)


@pytest.mark.parametrize("algo", ["ngransac", "ppo"])
@pytest.mark.parametrize("where, change, needle", [
    ("fixed", {"learning_rate": 1e30}, "fixed.learning_rate must be a finite number in (0, 0.1), got 1e+30"),
    ("fixed", {"learning_rate": 0.1}, "fixed.learning_rate must be a finite number in (0, 0.1), got 0.1"),
    # every searched value, not only the first point of the space (which the trainer's config checks)
    ("space", {"learning_rate": {"grid": [1e-4, 1e30]}},
     "space.learning_rate.grid[1] must be a finite number in (0, 0.1), got 1e+30"),
    ("space", {"learning_rate": {"choice": [1e-3, 0.0]}},
     "space.learning_rate.choice[1] must be a finite number in (0, 0.1), got 0.0"),
    ("space", {"learning_rate": {"loguniform": [1e-5, 1.0]}},
     "space.learning_rate.loguniform[1] must be a finite number in (0, 0.1), got 1.0"),
    ("space", {"learning_rate": {"uniform": [-1.0, 1e-3]}},
     "space.learning_rate.uniform[0] must be a finite number in (0, 0.1), got -1.0"),
])
def test_a_learning_rate_past_the_trainers_cap_is_refused_wherever_the_file_sets_it(algo, where, change, needle):
    import yaml

    data = yaml.safe_load(NGRANSAC if algo == "ngransac" else PPO)
    data["space"].pop("learning_rate", None)  # the tiny ngransac sweep searches it
    data[where] = {**data[where], **change}
    with pytest.raises(ValueError) as err:
        parse_sweep(data, "s.yaml")
    assert str(err.value) == f"s.yaml: {needle}"


def test_the_hint_and_the_key_come_from_the_errors_fields_not_from_their_words(monkeypatch):
    # Reworded refusals whose first word is no key: read from the text, the hint for the metric's value
    # and the file's key of a trainer field were lost; the errors' fields (OptionError.name,
    # FieldError.field) still name them.
    import yaml

    import agents.ngransac
    import agents.sweep_config
    from stereovo.options import OptionError
    from vo_gym.settings import FieldError

    class RewordedMetric(agents.sweep_config.MetricSpec):
        def __post_init__(self) -> None:
            try:
                super().__post_init__()
            except OptionError as err:
                raise OptionError(f"the held-out {err.name}{err.rule}", name=err.name, rule=err.rule) from None

    class RewordedConfig(agents.ngransac.NGRansacConfig):
        def __post_init__(self) -> None:
            try:
                super().__post_init__()
            except FieldError as err:
                raise FieldError(err.field, err.rule, subject=f"the trainer's {err.subject}") from None

    monkeypatch.setattr(agents.sweep_config, "MetricSpec", RewordedMetric)
    monkeypatch.setattr(agents.ngransac, "NGRansacConfig", RewordedConfig)
    data = yaml.safe_load(NGRANSAC)
    with pytest.raises(ValueError) as err:
        parse_sweep({**data, "metric": {**data["metric"], "budget": "1e3"}}, "s.yaml")
    assert str(err.value) == ("s.yaml: the held-out budget must be an integer >= 1 and <= 1000000000, got '1e3'"
                              " (YAML reads '1e3' as text; write 1000)")
    with pytest.raises(ValueError) as err:
        parse_sweep({**data, "fixed": {**data["fixed"], "pools": 1}}, "s.yaml")
    assert str(err.value) == "s.yaml: fixed.pools must be >= 2: the baseline is the mean loss of the pools"
    with pytest.raises(ValueError) as err:
        parse_sweep({**data, "space": {**data["space"], "entropy_weight": {"grid": [-1.0, 0.0]}}}, "s.yaml")
    assert str(err.value) == "s.yaml: space.entropy_weight (its first value) must be >= 0, got -1.0"
