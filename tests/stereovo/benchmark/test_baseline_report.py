"""stereovo.benchmark.baseline_report: docs/baselines.md rebuilt from a run folder's trials.csv."""

from __future__ import annotations

import json

import pytest

from stereovo import benchmark as bm
from stereovo.benchmark.baseline_report import enhancement_pairs, enhancement_section, grid_flags, write_baseline_report

METHODS = ["ransac", "ransac+polish", "ransac+guided", "msac"]


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    grid = bm.BenchmarkGrid(epsilons=(0.2, 0.5), noise_sigmas=(0.5,), score_aucs=(0.9,), ns=(60,),
                            frames_per_cell=2, max_iterations=200)
    rows = bm.run_benchmark(grid.trials(), bm.classical_estimators(METHODS, max_iterations=200), seed=3,
                            progress=False)
    folder = tmp_path_factory.mktemp("run")
    bm.write_outputs(rows, folder, plots=False)
    (folder / "run.json").write_text(json.dumps({"seed": 3, "grid": "a tiny grid", "wall_s": 12.0,
                                                 "methods": METHODS}))
    return folder, rows


def test_the_enhancement_rows_sit_under_their_textbook_row_without_the_guided_variants(run):
    summary = bm.summarize(run[1])
    assert enhancement_pairs(summary) == [("ransac", ["ransac+polish"])]
    table = "\n".join(enhancement_section(summary))
    assert "| `ransac` |" in table and "| &nbsp;&nbsp;`ransac+polish` |" in table and "guided" not in table
    delta = 100 * (summary.overall["ransac+polish"]["success_rate"] - summary.overall["ransac"]["success_rate"])
    assert f"| {delta:+.1f} points |" in table and "| textbook |" in table
    assert enhancement_section(bm.summarize([r for r in run[1] if r["method"] == "msac"])) == []


def test_the_report_is_rebuilt_from_the_runs_rows_and_settings(run, tmp_path):
    folder, rows = run
    path = write_baseline_report(folder, tmp_path, name="tiny")
    assert path == tmp_path / "tiny.md"
    text = path.read_text()
    assert "vo-gym baselines --seed 3 --out runs/tiny" in text and "--from runs/tiny --name tiny" in text
    assert "- Grid: a tiny grid." in text and f"{len({r['trial'] for r in rows})} frames x 4 methods in 12 s" in text
    assert all(f"- `{m}`: {bm.describe_method(m)}" in text for m in METHODS)
    summary = bm.summarize(rows)
    assert bm.summary_markdown(summary, {"max_iterations": None}, title="Results", level=2).rstrip() in text
    for figure in bm.PLOT_FILES:  # the run has no figures: they are drawn from trials.csv
        assert f"](img/tiny/{figure})" in text and (tmp_path / "img" / "tiny" / figure).stat().st_size > 0
    assert write_baseline_report(folder, tmp_path, name="tiny").read_text() == text  # same run, same report


def test_the_command_line_rebuilds_the_runs_grid():
    default = bm.DEFAULT_GRID.as_dict()
    assert grid_flags({"grid_axes": default}) == grid_flags({}) == ""
    assert grid_flags({"full": True, "grid_axes": bm.FULL_GRID.as_dict()}) == " --full --backend ray"
    axes = {**default, "outlier_kinds": ["hostile"], "epsilons": [0.5, 0.85], "ns": [200], "max_iterations": 300}
    flags = grid_flags({"grid_axes": axes})
    assert flags == " --epsilons 0.5,0.85 --ns 200 --outlier-kinds hostile --max-iterations 300"


def test_a_folder_without_trials_is_named(tmp_path):
    with pytest.raises(FileNotFoundError, match="vo-gym baselines --out"):
        write_baseline_report(tmp_path / "nothing", tmp_path)
