"""The ``vo-gym bench`` command on a tiny grid: its table, its CSV, its warm-up before timing, its
progress bar, and its argument errors."""

from __future__ import annotations

import csv
import importlib.util

import numpy as np
import pytest

from tests.support.cli import one_line_error
from vo_gym_cli.main import main

PEERS = [name for name, module in (("opencv", "cv2"), ("poselib", "poselib"), ("superansac:uniform", "pysuperansac"))
         if importlib.util.find_spec(module)]


def test_tiny_bench_prints_every_estimator_and_writes_the_csv(tmp_path, capsys):
    out = tmp_path / "bench.csv"
    assert main(["bench", "--ns", "60,120", "--epsilons", "0.3", "--frames", "3", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "ms/frame" in printed and "ours/this" in printed
    rows = list(csv.DictReader(out.open()))
    assert {(r["n"], r["estimator"]) for r in rows} == {
        (n, name) for n in ("60", "120") for name in ["ours:probabilistic", *PEERS]
    }
    for row in rows:
        assert float(row["median_ms"]) > 0
        assert 0.0 <= float(row["success"]) <= 1.0
    ours = [r for r in rows if r["estimator"] == "ours:probabilistic"]
    assert all(float(r["success"]) == 1.0 and float(r["median_rot_deg"]) < 0.2 for r in ours)
    # our own row's ratio to itself is 1.00
    assert all(line.split()[-1] == "1.00" for line in printed.splitlines() if "ours:probabilistic" in line)


def _recording_runners(monkeypatch, calls):
    """The bench's runners as two that record every frame they get: ours, and our estimator again as the one
    installed peer (OpenCV's place; the other peers count as not installed)."""
    from stereovo.benchmark import peers

    ours = peers.ours

    def make(name):
        inner = ours("probabilistic", "uniform")

        def run(frame, seed):
            calls.append((name, frame))
            return inner(frame, seed)

        return run

    monkeypatch.setattr(peers, "ours", lambda method, sampling: make("ours"))
    monkeypatch.setattr(peers, "opencv", lambda: make("peer"))
    for absent in ("poselib", "superansac"):
        monkeypatch.setattr(peers, absent, lambda *args, **kwargs: None)


def test_every_estimator_is_warmed_on_a_frame_no_cell_times_before_any_timing(monkeypatch, capsys):
    calls = []
    _recording_runners(monkeypatch, calls)
    assert main(["bench", "--ns", "60,120", "--epsilons", "0.3", "--frames", "2", "--no-progress"]) == 0
    assert "warming up: every estimator once on a frame of its own before timing" in capsys.readouterr().out
    warm, timed = calls[:2], calls[2:]
    assert [name for name, _ in warm] == ["ours", "peer"] and warm[0][1] is warm[1][1]
    assert len(timed) == 2 * 2 * 2  # cells x frames x runners
    assert not any(np.array_equal(warm[0][1].curr, frame.curr) for _, frame in timed)


def test_the_warm_up_changes_no_result_but_the_times(tmp_path, monkeypatch):
    from vo_gym_cli.commands import bench

    argv = ["bench", "--ns", "80", "--epsilons", "0.5", "--frames", "3", "--no-peers", "--no-progress"]
    assert main([*argv, "--out", str(tmp_path / "warm.csv")]) == 0
    monkeypatch.setattr(bench, "warm_up", lambda *args: None)
    assert main([*argv, "--out", str(tmp_path / "cold.csv")]) == 0
    untimed = lambda name: [(r["estimator"], r["success"], r["median_rot_deg"])  # noqa: E731
                            for r in csv.DictReader((tmp_path / name).open())]
    assert untimed("warm.csv") == untimed("cold.csv")


def test_no_progress_hides_the_bar(capsys):
    argv = ["bench", "--ns", "60", "--epsilons", "0.3", "--frames", "1", "--no-peers"]
    assert main(argv) == 0
    assert "bench: 100%" in capsys.readouterr().err
    assert main([*argv, "--no-progress"]) == 0
    assert "bench:" not in capsys.readouterr().err


@pytest.mark.parametrize("more, needle", [
    (["--superansac-rigid"], "--superansac-rigid applies to the SupeRANSAC peer, which --no-peers skips"),
    (["--superansac-sampler", "uniform"], "--superansac-sampler uniform applies to the SupeRANSAC peer, which --no-peers"),
])
def test_a_superansac_option_with_no_peers_is_refused(tmp_path, capsys, more, needle):
    assert main(["bench", "--no-peers", *more, "--out", str(tmp_path / "b.csv")]) == 2
    assert needle in one_line_error(capsys, "bench")
    assert not (tmp_path / "b.csv").exists()
