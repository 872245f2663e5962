"""scripts/bench_env.py: the environment speed benchmark runs every mode and reports against the target."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "bench_env.py"


def _load():
    spec = importlib.util.spec_from_file_location("bench_env", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_bench_env_reports_every_mode_and_the_target(tmp_path, capsys):
    out = tmp_path / "bench.json"
    args = ["--n", "40", "--budget", "4", "--n-frames", "3", "--steps", "8", "--warmup", "2", "--repeats", "1",
            "--target", "1e9", "--json", str(out)]
    assert _load().main(args) == 0
    printed = capsys.readouterr().out
    results = json.loads(out.read_text())
    for mode in ("single", "sync", "async"):
        assert results[mode]["steps_per_s"] > 0
        assert results[mode]["steps"] == 8
        assert any(line.startswith(mode) for line in printed.splitlines())
    assert results["async"]["cores"] >= 1 and results["sync"]["cores"] == 1
    assert results["target_met"] == {"single": False, "sync": False, "async": False}
    assert "target >= 1e+09 steps/s per core: single MISSED, sync MISSED, async MISSED" in printed
    assert set(results["breakdown"]) == {"simulation_ms", "features_ms", "estimator_ms"}
