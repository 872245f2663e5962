"""The ``vo-gym bench`` command on a tiny grid: its table, its CSV, and its argument errors."""

from __future__ import annotations

import csv
import importlib.util

import pytest

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
