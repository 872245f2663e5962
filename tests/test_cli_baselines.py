"""The ``vo-gym baselines`` command end to end, and the report script."""

from __future__ import annotations

import csv
import importlib.util
import json
from pathlib import Path

import pytest

from stereovo.benchmark import PLOT_FILES, TIME_COLUMNS, benchmark_methods
from vo_gym.cli import main

TINY = ["--methods", "ransac,msac", "--epsilons", "0.2,0.6", "--aucs", "0.9", "--ns", "80", "--frames-per-cell", "2",
        "--max-iterations", "300", "--seed", "11", "--no-progress"]
TABLES = ["trials.csv", "summary.csv", "cells.csv", "summary.md", "claims.md", "run.json"]


def _rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as fh:
        return list(csv.DictReader(fh))


def _without_time(rows):
    return [{k: v for k, v in r.items() if k not in TIME_COLUMNS} for r in rows]


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    root = tmp_path_factory.mktemp("baselines")
    one, two = root / "w1", root / "w2"
    code_one = main(["baselines", *TINY, "--workers", "1", "--out", str(one)])
    code_two = main(["baselines", *TINY, "--workers", "2", "--out", str(two), "--no-plots"])
    return one, two, code_one, code_two


def test_writes_every_file_and_the_table(runs, capsys):
    one, _, code, _ = runs
    assert code == 0
    for name in (*TABLES, *PLOT_FILES):
        assert (one / name).is_file() and (one / name).stat().st_size > 0, name
    rows = _rows(one / "trials.csv")
    assert len(rows) == 2 * 2 * 2  # cells x frames x methods
    assert [r["method"] for r in rows[:2]] == ["ransac", "msac"]
    assert {r["epsilon"] for r in rows} == {"0.2", "0.6"}
    summary = _rows(one / "summary.csv")
    assert [r["method"] for r in summary] == ["ransac", "msac"] and all(r["frames"] == "4" for r in summary)
    text = (one / "summary.md").read_text()
    for needle in ("success", "rot err med [deg]", "trans err med [m]", "inlier precision", "inlier recall",
                   "hypotheses", "point checks", "time med [ms]", "max_iterations = 300", "`ransac`"):
        assert needle in text, needle
    claims = (one / "claims.md").read_text()
    assert "not measured" in claims and "PROSAC" in claims
    settings = json.loads((one / "run.json").read_text())
    assert settings["seed"] == 11 and settings["methods"] == ["ransac", "msac"] and settings["workers"] == 1


def test_worker_count_does_not_change_the_csv(runs):
    one, two, _, code = runs
    assert code == 0
    assert _without_time(_rows(one / "trials.csv")) == _without_time(_rows(two / "trials.csv"))
    assert not (two / "error_cdf.png").exists()


def test_prints_the_table_and_the_verdicts(tmp_path, capsys):
    argv = ["baselines", "--methods", "ransac", "--epsilons", "0.3", "--aucs", "0.75", "--ns", "60", "--frames-per-cell", "1",
            "--no-progress", "--no-plots", "--out", str(tmp_path / "run")]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "| `ransac` | 1 |" in out and "success" in out and "prosac-iterations" in out and "not measured" in out
    assert "1 frames x 1 methods" in out


def test_unknown_method_exits_nonzero_and_names_it(tmp_path, capsys):
    code = main(["baselines", "--methods", "ransac,bogosac", "--out", str(tmp_path / "x"), "--no-progress"])
    assert code != 0
    err = capsys.readouterr().err
    assert "bogosac" in err and "available" in err and "ransac" in err
    assert not (tmp_path / "x").exists()


@pytest.mark.parametrize(
    "argv, needle",
    [
        (["--epsilons", "0.2,1.5"], "outlier_ratio"),
        (["--outlier-kinds", "ghosts"], "unknown outlier kind"),
    ],
)
def test_bad_grid_values_exit_nonzero(tmp_path, capsys, argv, needle):
    assert main(["baselines", *argv, "--out", str(tmp_path / "x"), "--no-progress"]) == 2
    assert needle in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


@pytest.mark.parametrize(
    "argv, needle",
    [(["--workers", "0"], "--workers must be >= 1"), (["--seed", "-1"], "--seed must be >= 0"),
     (["--ns", "a,b"], "--ns")],
)
def test_bad_options_are_argparse_errors(tmp_path, capsys, argv, needle):
    with pytest.raises(SystemExit) as exc:
        main(["baselines", *argv, "--out", str(tmp_path / "x")])
    assert exc.value.code != 0 and needle in capsys.readouterr().err


def test_help_states_the_default_grid(capsys):
    from stereovo.benchmark import DEFAULT_GRID

    with pytest.raises(SystemExit) as exc:
        main(["baselines", "--help"])
    assert exc.value.code == 0
    text = capsys.readouterr().out
    g = DEFAULT_GRID
    for needle in ("--methods", "--full", "--workers", "--seed", "--out", "--frames-per-cell",
                   "epsilon " + ",".join(f"{e:g}" for e in g.epsilons), "AUC " + ",".join(f"{a:g}" for a in g.score_aucs),
                   "N " + ",".join(map(str, g.ns)), f"{g.frames_per_cell} frames per cell",
                   f"max {g.max_iterations} hypotheses"):
        assert needle in text, needle


def test_list_methods(capsys):
    assert main(["baselines", "--list-methods"]) == 0
    out = capsys.readouterr().out
    assert all(name in out for name in benchmark_methods())


def test_report_script_builds_docs_from_a_run(runs, tmp_path):
    one = runs[0]
    path = Path(__file__).resolve().parent.parent / "scripts" / "make_baseline_report.py"
    spec = importlib.util.spec_from_file_location("make_baseline_report", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    docs = tmp_path / "docs"
    assert module.main(["--from", str(one), "--docs", str(docs)]) == 0
    text = (docs / "baselines.md").read_text()
    assert "## Claims of the seed vs our numbers" in text and "| `msac` |" in text
    for name in PLOT_FILES:
        assert f"](img/baselines/{name})" in text and (docs / "img" / "baselines" / name).is_file()
    assert module.main(["--from", str(tmp_path / "missing"), "--docs", str(docs)]) == 2
    redrawn = tmp_path / "redrawn"
    assert module.main(["--from", str(runs[1]), "--docs", str(redrawn)]) == 0  # run without PNGs
    assert all((redrawn / "img" / "baselines" / name).stat().st_size > 0 for name in PLOT_FILES)
