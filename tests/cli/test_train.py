"""``vo-gym train`` (vo_gym_cli.commands.train): --algo ngransac flags reach the config and resume
works, --algo ppo options, --algo adaptive within a time budget, and a non-empty --out kept unless
--overwrite or a --resume that continues the run there."""

from __future__ import annotations

import argparse
import json

import pytest

from agents.checkpoint import load_checkpoint
from agents.ngransac import NGRansacConfig
from agents.ppo.config import PPOConfig
from tests.support.cli import ROOT, exit_code, one_line_error
from vo_gym_cli.commands import train
from vo_gym_cli.main import main


TINY = ["--frames", "4", "--budget", "4", "--pools", "2", "--eval-every", "2", "--eval-frames", "2",
        "--frames-per-sequence", "3", "--no-progress"]


pytest.importorskip("stable_baselines3")


def _config(*argv: str) -> PPOConfig:
    parser = argparse.ArgumentParser()
    train.add_parser(parser)
    return train.ppo_config_from_args(parser.parse_args(["--algo", "ppo", *argv]))


def test_train_ngransac_writes_checkpoint_with_flags_and_defaults_and_resumes(tmp_path):
    assert main(["train", "--algo", "ngransac", "--out", str(tmp_path), "--lr", "2e-4", "--max-grad-norm", "0", *TINY]) == 0
    checkpoint = tmp_path / "ngransac-supervised.pt"
    _, payload = load_checkpoint(checkpoint)
    config = payload["config"]
    assert (config["budget"], config["pools"], config["frames"], config["learning_rate"]) == (4, 2, 4, 2e-4)
    assert config["max_grad_norm"] is None  # 0 switches clipping off
    assert config["entropy_weight"] == NGRansacConfig().entropy_weight  # not given: the config's default
    summary = json.loads((tmp_path / "training.json").read_text())
    assert summary["steps"] == 4 and [h["step"] for h in summary["history"]] == [2, 4]

    assert main(["train", "--algo", "ngransac", "--out", str(tmp_path), "--resume", str(checkpoint),
                 "--frames", "6", "--no-progress"]) == 0
    assert json.loads((tmp_path / "training.json").read_text())["steps"] == 6


def test_train_ngransac_rejects_bad_settings(tmp_path, capsys):
    assert main(["train", "--algo", "ngransac", "--out", str(tmp_path), "--pools", "1", "--no-progress"]) == 2
    assert "pools" in capsys.readouterr().err


@pytest.mark.parametrize("every", [250, 1000, 2000, 3])
def test_eval_every_is_taken_as_given(every):
    # 250 was once the shared option's default, and a given 250 silently became PPOConfig's 2000.
    assert _config("--eval-every", str(every)).eval_every == every


def test_options_left_out_keep_the_config_defaults():
    config, default = _config(), PPOConfig()
    assert config == default
    assert config.eval_every == 2000


def test_ppo_options_are_mapped_to_their_fields():
    config = _config("--epsilon", "0.4:0.7", "--frames-per-episode", "5", "--ppo-lr", "3e-4", "--max-minutes", "2",
                     "--eval-n", "200", "--n-envs", "1", "--batch-size", "64")
    assert config.epsilon_range == (0.4, 0.7)
    assert (config.n_frames, config.learning_rate, config.max_wall_s) == (5, 3e-4, 120.0)
    assert (config.eval_n_correspondences, config.n_envs, config.batch_size) == (200, 1, 64)


def _train_tiny_adaptive(torch, tmp_path, *extra: str):
    """``vo-gym train --algo adaptive`` for two 2-frame episodes of 60 matches; the output folder."""
    out = tmp_path / "ad"
    threads = torch.get_num_threads()
    try:
        assert main(["train", "--algo", "adaptive", "--minutes", "0.5", "--clock", "cpu", "--max-episodes", "2",
                     "--frames-per-episode", "2", "--n-correspondences", "60", "--seed", "3", "--no-progress",
                     *extra, "--out", str(out)]) == 0
    finally:
        torch.set_num_threads(threads)
    return out


def test_train_adaptive_within_a_time_budget_writes_a_usable_in_frame_sampler(tmp_path, capsys):
    torch = pytest.importorskip("torch")
    from agents import LearnedEstimator
    from agents.adaptive.checkpoint import load_adaptive
    from stereovo.simulation import SimulationConfig, simulate_frame

    out = _train_tiny_adaptive(torch, tmp_path)
    summary = json.loads((out / "training.json").read_text())
    assert summary["algo"] == "adaptive" and summary["episodes"] == 2 and summary["frames"] == 4
    assert summary["config"]["minutes"] == 0.5 and summary["config"]["clock"] == "cpu"
    assert summary["config"]["seed"] == 3 and summary["config"]["n"] == 60
    _, payload = load_adaptive(out / "adaptive.pt")
    assert payload["config"]["max_episodes"] == 2
    assert f"checkpoint: {out / 'adaptive.pt'}" in capsys.readouterr().out
    frame = simulate_frame(SimulationConfig(n_correspondences=60, outlier_ratio=0.3), rng=1)
    est = LearnedEstimator(out / "adaptive.pt", budget=8).estimate(frame.prev, frame.curr, frame.camera, frame.scores)
    assert est.sampler_kind == "in-frame" and est.n_hypotheses == 8


def test_train_adaptive_with_a_prior_file_and_randomised_episodes(tmp_path, capsys):
    torch = pytest.importorskip("torch")
    from agents.adaptive.checkpoint import load_adaptive

    out = _train_tiny_adaptive(torch, tmp_path, "--prior", str(ROOT / "agents" / "checkpoints" / "ngransac-supervised.pt"),
                               "--domain-randomisation")
    net, payload = load_adaptive(out / "adaptive.pt")
    assert payload["config"]["domain_randomisation"] is True and net.prior is not None
    assert "domain-randomised episodes" in capsys.readouterr().out


@pytest.mark.parametrize("argv, needle", [
    (["--prior", "nope"], "--prior 'nope' is not a shipped one-shot sampler (shipped: ngransac-supervised"),
    (["--prior", str(ROOT / "agents" / "checkpoints" / "adaptive-pg.pt")], "adaptive-pg.pt' is an in-frame sampler; a prior is a one-shot one"),
    (["--resume", str(ROOT / "agents" / "checkpoints" / "ppo.pt")], "a one-shot checkpoint; --algo adaptive"),
    (["--prior", "ppo", "--resume", str(ROOT / "agents" / "checkpoints" / "adaptive-pg.pt")], "--prior starts a fresh network, --resume continues"),
])
def test_train_adaptive_errors_are_one_line(tmp_path, capsys, argv, needle):
    pytest.importorskip("torch")
    assert main(["train", "--algo", "adaptive", "--minutes", "0.01", *argv, "--out", str(tmp_path / "t")]) == 2
    assert needle in one_line_error(capsys, "train")
    assert not (tmp_path / "t").exists()  # refused before --out was made


@pytest.mark.parametrize("algo, make, needle", [
    ("ngransac", lambda p: p.write_text("junk"), "--resume: checkpoint "),
    ("adaptive", lambda p: p.write_bytes(b"PK\x03\x04 truncated"), "--resume: checkpoint "),
    ("ngransac", lambda p: p.write_bytes((ROOT / "agents" / "checkpoints" / "adaptive-pg.pt").read_bytes()),
     "an in-frame checkpoint; --algo ngransac continues a one-shot one"),
])
def test_a_checkpoint_to_resume_is_read_before_out_is_made(tmp_path, capsys, algo, make, needle):
    pytest.importorskip("torch")
    path = tmp_path / "given.pt"
    make(path)
    budget = ["--frames", "2"] if algo == "ngransac" else ["--minutes", "0.01"]
    assert main(["train", "--algo", algo, "--resume", str(path), *budget, "--out", str(tmp_path / "t")]) == 2
    assert needle in one_line_error(capsys, "train")
    assert not (tmp_path / "t").exists()


def test_train_adaptive_minutes_must_be_positive(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["train", "--algo", "adaptive", "--minutes", "0", "--out", str(tmp_path / "t")])
    assert exc.value.code == 2
    assert "--minutes must be > 0.0" in one_line_error(capsys, "train")


@pytest.mark.parametrize("argv, needle", [
    (["--algo", "adaptive", "--max-minutes", "1"], "--algo adaptive does not take --max-minutes 1.0 (an option of ppo; here: --minutes)"),
    (["--algo", "adaptive", "--frames", "10", "--lr", "0.01"], "--frames 10 (an option of ngransac; here: --max-episodes or --minutes), --lr 0.01"),
    (["--algo", "ppo", "--minutes", "3"], "--algo ppo does not take --minutes 3.0 (an option of adaptive; here: --max-minutes)"),
    (["--algo", "ngransac", "--timesteps", "5", "--prior", "ppo"], "--algo ngransac does not take --prior ppo (an option of adaptive), --timesteps 5"),
    (["--algo", "adaptive", "--epsilon", "0.5"], "--epsilon 0.5 (an option of ngransac and ppo)"),
    # typed at their defaults, still options another trainer reads
    (["--algo", "adaptive", "--epsilon", "0.3:0.9"], "--algo adaptive does not take --epsilon 0.3:0.9 (an option of"),
    (["--algo", "ngransac", "--timesteps", "20000"], "--algo ngransac does not take --timesteps 20000 (an option of ppo)"),
    (["--algo", "ppo", "--loss=supervised"], "--algo ppo does not take --loss supervised (an option of ngransac)"),
])
def test_an_option_of_another_trainer_is_refused_not_ignored(tmp_path, capsys, argv, needle):
    assert main(["train", *argv, "--out", str(tmp_path / "t")]) == 2
    assert needle in one_line_error(capsys, "train")
    assert not (tmp_path / "t").exists()  # refused before anything ran


def test_every_option_belongs_to_a_trainer():
    parser = argparse.ArgumentParser()
    train.add_parser(parser)
    common = {"algo", "out", "overwrite", "seed", "resume", "no_progress"}
    dests = set(vars(parser.parse_args([]))) - common
    assert dests == set().union(*train.USED_BY.values())


def test_a_non_empty_out_is_refused_unless_overwrite_which_drops_the_old_curves(tmp_path, capsys):
    out = tmp_path / "run"
    (out / "tb").mkdir(parents=True)
    stale = out / "tb" / "events.out.tfevents.1.old-run"
    stale.write_bytes(b"an earlier run's curves")
    (out / "notes.txt").write_text("mine")
    assert main(["train", "--algo", "ngransac", *TINY, "--out", str(out)]) == 2
    line = one_line_error(capsys, "train")
    assert f"--out '{out}' is not empty (2 entries); pass --overwrite to replace the run there, or --resume" in line
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt", "tb"] and stale.exists()  # refused before training
    assert main(["train", "--algo", "ngransac", *TINY, "--overwrite", "--out", str(out)]) == 0
    assert not stale.exists() and len(list((out / "tb").glob("events.out.tfevents.*"))) == 1
    assert (out / "notes.txt").read_text() == "mine" and (out / "ngransac-supervised.pt").is_file()
    # a checkpoint from elsewhere starts another run: the folder's is kept
    elsewhere = tmp_path / "elsewhere.pt"
    elsewhere.write_bytes((out / "ngransac-supervised.pt").read_bytes())
    assert main(["train", "--algo", "ngransac", "--resume", str(elsewhere), "--frames", "6", "--no-progress",
                 "--out", str(out)]) == 2
    assert "is not empty" in one_line_error(capsys, "train")


@pytest.mark.parametrize("algo, bad", [("ppo", ["--batch-size", "100000"]), ("ppo", ["--width", "1024", "--blocks", "20"])])
def test_overwrite_keeps_the_old_run_when_the_new_settings_are_refused(tmp_path, capsys, algo, bad):
    out = tmp_path / "run"
    (out / "tb" / "PPO_1").mkdir(parents=True)
    (out / "checkpoints").mkdir()
    stale = [out / "tb" / "PPO_1" / "events.out.tfevents.1.old-run", out / "checkpoints" / "ppo_256_steps.zip"]
    for path in stale:
        path.write_bytes(b"an earlier run's")
    assert main(["train", "--algo", algo, *bad, "--overwrite", "--out", str(out), "--no-progress"]) == 2
    one_line_error(capsys, "train")
    assert all(path.exists() for path in stale)  # deleted only once the new run can start


def test_adaptive_resuming_inside_out_still_needs_overwrite(tmp_path, capsys):
    out = tmp_path / "ad"
    out.mkdir()
    checkpoint = out / "adaptive.pt"
    checkpoint.write_bytes((ROOT / "agents" / "checkpoints" / "adaptive-pg.pt").read_bytes())
    # adaptive's --resume starts fresh training from the weights, rewriting training.jsonl
    assert main(["train", "--algo", "adaptive", "--resume", str(checkpoint), "--minutes", "0.01",
                 "--out", str(out)]) == 2
    line = one_line_error(capsys, "train")
    assert line.endswith("pass --overwrite to replace the run there"), line


def test_out_help_says_which_trainers_write_tensorboard_logs(capsys):
    with pytest.raises(SystemExit):
        main(["train", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "ngransac and ppo also write TensorBoard logs under tb/, adaptive its log windows in training.jsonl" in text
    assert "directory for checkpoints and TensorBoard logs" not in text


def _tiny_ngransac(tmp_path):
    out = tmp_path / "ng"
    assert main(["train", "--algo", "ngransac", "--out", str(out), *TINY]) == 0
    return out / "ngransac-supervised.pt"


def test_resume_refuses_every_option_the_checkpoint_fixes_in_one_line(tmp_path, capsys):
    checkpoint = _tiny_ngransac(tmp_path)
    capsys.readouterr()
    fixed = ["--budget", "3", "--pools", "2", "--lr", "0.05", "--loss", "self-supervised", "--epsilon", "0.5"]
    assert main(["train", "--algo", "ngransac", "--resume", str(checkpoint), "--frames", "6", *fixed, "--seed", "7",
                 "--out", str(tmp_path / "z")]) == 2
    assert one_line_error(capsys, "train") == (
        "vo-gym train: error: --budget 3, --pools 2, --lr 0.05, --loss self-supervised, --epsilon 0.5: fixed by the "
        f"checkpoint --resume {checkpoint}, whose run goes on with its own settings; a resumed ngransac run takes only "
        "--seed, --frames, --eval-every (start a new run to change the others)")
    assert not (tmp_path / "z").exists()  # refused before --out was made


def test_resume_applies_the_options_it_takes(tmp_path):
    checkpoint = _tiny_ngransac(tmp_path)
    out = tmp_path / "z"
    assert main(["train", "--algo", "ngransac", "--resume", str(checkpoint), "--frames", "6", "--seed", "7",
                 "--eval-every", "1", "--no-progress", "--out", str(out)]) == 0
    _, payload = load_checkpoint(out / "ngransac-supervised.pt")
    config = payload["config"]
    assert (config["seed"], config["eval_every"], config["frames"], config["budget"], config["pools"]) == (7, 1, 6, 4, 2)
    assert [h["step"] for h in payload["trainer_state"]["history"]] == [2, 4, 5, 6]


PPO_TINY = ["--timesteps", "16", "--n-envs", "1", "--n-steps", "16", "--batch-size", "16", "--n-epochs", "1",
            "--n-correspondences", "40", "--frames-per-episode", "4", "--eval-n", "40", "--eval-frames", "4",
            "--eval-every", "16", "--width", "8", "--blocks", "1", "--no-progress"]


def test_ppo_resume_refuses_what_the_zip_fixes_and_applies_what_it_takes(tmp_path, capsys):
    from agents.ppo.archive import load_ppo, read_ppo_config

    out = tmp_path / "ppo"
    assert main(["train", "--algo", "ppo", *PPO_TINY, "--out", str(out)]) == 0
    zip_path = out / "ppo.zip"
    capsys.readouterr()
    assert main(["train", "--algo", "ppo", "--resume", str(zip_path), "--timesteps", "24", "--budget", "4",
                 "--ppo-lr", "0.05", "--reward-mode", "inliers", "--env-id", "vo_gym/StereoVOHard-v0",
                 "--out", str(tmp_path / "z")]) == 2
    line = one_line_error(capsys, "train")
    assert line.startswith("vo-gym train: error: --budget 4, --ppo-lr 0.05, --reward-mode inliers, --env-id "
                           f"vo_gym/StereoVOHard-v0: fixed by the checkpoint --resume {zip_path}"), line
    assert line.endswith("a resumed ppo run takes only --n-envs, --seed, --timesteps, --eval-every, --vec-env, "
                         "--checkpoint-every, --max-minutes (start a new run to change the others)")
    assert not (tmp_path / "z").exists()
    # what it takes is applied; what is left out stays the zip's (eval_frames 4, not PPOConfig's 100)
    assert main(["train", "--algo", "ppo", "--resume", str(zip_path), "--timesteps", "32", "--seed", "5",
                 "--eval-every", "8", "--no-progress", "--out", str(out)]) == 0
    config = read_ppo_config(zip_path)
    assert (config.timesteps, config.seed, config.eval_every) == (32, 5, 8)
    assert (config.eval_frames, config.width, config.n_correspondences, config.budget) == (4, 8, 40, PPOConfig().budget)
    assert load_ppo(zip_path).seed == 5  # the continuation's action noise is seeded anew too


def test_help_states_each_trainers_default_read_from_its_config(capsys, monkeypatch):
    from agents.adaptive.train import AdaptiveTrainConfig

    monkeypatch.setenv("COLUMNS", "1000")  # one line per option: no flag broken at its hyphen
    with pytest.raises(SystemExit):
        main(["train", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    ng, ppo, ad = NGRansacConfig(), PPOConfig(), AdaptiveTrainConfig()
    assert f"hypotheses per pool (ngransac) or per frame (ppo) (default: ngransac {ng.budget}, ppo {ppo.budget})" in text
    assert f"frames per evaluation (default: ngransac {ng.eval_frames}, ppo {ppo.eval_frames})" in text
    assert f"(default: ngransac {ng.eval_every}, ppo {ppo.eval_every})" in text
    assert f"matches per training frame (default: ppo {ppo.n_correspondences}, adaptive {ad.n};" in text
    assert f"PPO environment steps (default {ppo.timesteps})" in text
    assert ("takes only (ngransac: --seed, --frames, --eval-every; ppo: --n-envs, --seed, --timesteps, --eval-every, "
            "--vec-env, --checkpoint-every, --max-minutes;") in text


@pytest.mark.parametrize("env_id, needle", [
    ("vo_gym/StereoVOAdaptive-v0", "--env-id vo_gym/StereoVOAdaptive-v0 is an in-frame environment (its action also "
                                   "stops the search); PPO trains on a step id (vo_gym/StereoVO-v0, "),
    ("vo_gym/StereoVOImages-v0", "--env-id vo_gym/StereoVOImages-v0 is an image environment; PPO trains on simulated"),
    ("CartPole-v1", "--env-id 'CartPole-v1' is not a vo_gym step environment; PPO trains on one of: vo_gym/StereoVO-v0"),
    ("StereoVO-v0", "--env-id 'StereoVO-v0' is not a vo_gym step environment (did you mean 'vo_gym/StereoVO-v0'?)"),
])
def test_ppo_refuses_an_env_id_it_cannot_train_on_before_out_is_made(tmp_path, capsys, env_id, needle):
    assert main(["train", "--algo", "ppo", "--env-id", env_id, *PPO_TINY, "--out", str(tmp_path / "t")]) == 2
    assert needle in one_line_error(capsys, "train")
    assert not (tmp_path / "t").exists()


@pytest.mark.parametrize("argv, message", [
    (["--algo", "ppo", "--timesteps", "1" + "0" * 400],
     "--timesteps must be an integer >= 1 and <= 1000000000, got ~1e+400 (an integer of 401 digits)"),
    (["--algo", "ppo", "--timesteps", "16", "--batch-size", "100000"],
     "--batch-size=100000 exceeds the rollout size n_steps * n_envs = 512"),
    (["--algo", "ngransac", "--frames", "2", "--pools", "1"], "--pools must be >= 2"),
    (["--algo", "adaptive", "--minutes", "0.01", "--max-episodes", "1" + "0" * 20],
     "--max-episodes must be None or an integer >= 1 and <= 1000000000, got 100000000000000000000"),
])
def test_a_setting_the_trainer_refuses_is_named_before_out_is_made(tmp_path, capsys, argv, message):
    assert main(["train", *argv, "--no-progress", "--out", str(tmp_path / "t")]) == 2
    line = one_line_error(capsys, "train")
    assert line.startswith(f"vo-gym train: error: {message}"), line
    assert not (tmp_path / "t").exists()


@pytest.mark.parametrize("algo, argv, refusal, message", [
    # a refusal whose words do not name the field still names the option that set it
    ("ppo", ["--frames-per-episode", "9"], ("n_frames", " are too many for one episode", "the episode length"),
     "--frames-per-episode are too many for one episode"),
    ("ngransac", ["--pools", "3"], ("pools", "share one baseline, and three of them ...", ""),
     "--pools: share one baseline, and three of them ..."),
    ("adaptive", ["--n-correspondences", "40"], ("n", " must be more matches", "the frame's size"),
     "--n-correspondences must be more matches"),
])
def test_a_config_refusal_names_the_option_of_its_field_not_of_its_words(tmp_path, capsys, monkeypatch, algo, argv,
                                                                           refusal, message):
    from vo_gym.settings import FieldError

    field, rule, subject = refusal
    assert field not in str(FieldError(field, rule, subject=subject)).split()

    def refuse(self):
        raise FieldError(field, rule, subject=subject)

    from agents.adaptive.train import AdaptiveTrainConfig

    config_class = {"ngransac": NGRansacConfig, "ppo": PPOConfig, "adaptive": AdaptiveTrainConfig}[algo]
    monkeypatch.setattr(config_class, "__post_init__", refuse)
    assert main(["train", "--algo", algo, *argv, "--no-progress", "--out", str(tmp_path / "t")]) == 2
    assert one_line_error(capsys, "train") == f"vo-gym train: error: {message}"
    assert not (tmp_path / "t").exists()


def test_a_config_refusal_without_a_field_keeps_its_words_even_when_they_start_with_a_fields_name(tmp_path, capsys,
                                                                                                   monkeypatch):
    def refuse(self):
        raise ValueError("pools must be >= 2")  # no FieldError: which option set it is not read from the words

    monkeypatch.setattr(NGRansacConfig, "__post_init__", refuse)
    assert main(["train", "--algo", "ngransac", "--pools", "1", "--no-progress", "--out", str(tmp_path / "t")]) == 2
    assert one_line_error(capsys, "train") == "vo-gym train: error: pools must be >= 2"


@pytest.mark.parametrize("algo, flag", [("ngransac", "--lr"), ("ppo", "--ppo-lr")])
@pytest.mark.parametrize("value, rule", [
    ("1e30", "must be < 0.1, got 1e+30"), ("0.1", "must be < 0.1, got 0.1"), ("5", "must be < 0.1, got 5.0"),
    ("0", "must be > 0.0, got 0.0"), ("-1e-3", "must be > 0.0, got -0.001"), ("nan", "must be finite, got 'nan'"),
    ("inf", "must be finite, got 'inf'"), ("-inf", "must be finite, got '-inf'"), ("1e400", "must be finite, got '1e400'"),
])
def test_a_learning_rate_that_cannot_train_is_refused_before_out_is_made(tmp_path, capsys, algo, flag, value, rule):
    # 1e30 used to start and fail mid-training (NG-RANSAC: a traceback; PPO: NaN logits), --out already made
    assert exit_code(["train", "--algo", algo, f"{flag}={value}", "--out", str(tmp_path / "t")]) == 2
    assert one_line_error(capsys, "train") == f"vo-gym train: error: {flag} {rule}"
    assert not (tmp_path / "t").exists()


def test_the_command_lines_learning_rate_cap_is_the_trainers():
    from agents.training_limits import MAX_LEARNING_RATE
    from vo_gym_cli.commands.arguments import max_learning_rate

    assert max_learning_rate() == MAX_LEARNING_RATE
    below = MAX_LEARNING_RATE * (1 - 1e-9)
    assert NGRansacConfig(learning_rate=below).learning_rate == below and PPOConfig(learning_rate=below).learning_rate == below
    for config in (NGRansacConfig, PPOConfig):
        with pytest.raises(ValueError, match=r"learning_rate must be a finite number in \(0, 0\.1\), got 0\.1$"):
            config(learning_rate=MAX_LEARNING_RATE)
