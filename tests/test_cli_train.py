"""`vo-gym train --algo ngransac`: flags reach the config, unset ones keep the config's defaults, resume works."""

import json

import pytest

from agents.checkpoint import load_checkpoint
from agents.ngransac import NGRansacConfig
from vo_gym_cli.main import main

TINY = ["--frames", "4", "--budget", "4", "--pools", "2", "--eval-every", "2", "--eval-frames", "2",
        "--frames-per-sequence", "3", "--no-progress"]


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
