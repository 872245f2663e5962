"""scripts/mutation_test.py and its data (docs/mutation-verdicts.toml): every module and test the data
names exists, and the report is written from stored results with the data's verdicts."""

from __future__ import annotations

import ast
import json
from pathlib import Path

from tests.support.scripts import SCRIPTS, load_script

ROOT = SCRIPTS.parent


def _test_functions(path: Path) -> set[str]:
    return {node.name for node in ast.parse(path.read_text()).body
            if isinstance(node, ast.FunctionDef) and node.name.startswith("test")}


def test_every_module_and_selected_test_of_the_data_exists():
    verdicts = load_script("mutation_test").load_verdicts(ROOT / "docs" / "mutation-verdicts.toml")
    assert [m.name for m in verdicts.modules][:2] == ["rewards", "termination"]
    for module in verdicts.modules:
        assert (ROOT / module.path).is_file(), module.path
        for test in module.tests:
            file, _, name = test.partition("::")
            assert (ROOT / file).is_file(), test
            assert not name or name in _test_functions(ROOT / file), test
    for test in {t.split(" ")[0] for t in verdicts.addressed.values()}:
        file, _, name = f"tests/{test}".partition("::")
        assert name in _test_functions(ROOT / file), test


def test_the_report_is_written_from_stored_results(tmp_path):
    runner = load_script("mutation_test")
    equivalent = "vo_gym.rewards.x_pose_error_ratio__mutmut_12"  # an equivalent mutant of the data
    results = {"rewards": {"note": "done in 1.0 min", "diff": {equivalent: "-a / b\n+a * b",
                                                              "vo_gym.rewards.x_other__mutmut_1": "-x\n+y"},
                           "status": {equivalent: "survived", "vo_gym.rewards.x_other__mutmut_1": "survived",
                                      "vo_gym.rewards.x_other__mutmut_2": "killed"}}}
    store, report = tmp_path / "results.json", tmp_path / "report.md"
    store.write_text(json.dumps(results))
    assert runner.main(["--report-only", "--report", str(report), "--results", str(store)]) == 0
    text = report.read_text()
    row = next(line for line in text.splitlines() if line.startswith("| `vo_gym/rewards.py` |"))
    # 3 mutants: 1 killed, 1 survived, 1 equivalent; kill rate 1 / (1 + 1)
    assert "| 3 | 1 | 0 | 1 | 1 | 0 | 0 | 50.0 % | done in 1.0 min |" in row
    assert f"- `{equivalent}` (equivalent): rot_err_deg / SUCCESS_ROT_DEG" in text
    assert "- `vo_gym.rewards.x_other__mutmut_1` (survived): not yet addressed: needs a test" in text
    assert "  +a * b" in text and "| `stereovo/geometry.py` |" in text  # every module has its row ("not run")


def test_report_only_without_a_results_file_leaves_the_report_alone(tmp_path, capsys):
    # Rewritten from itself, the report kept each module's counts but lost its survivors' diffs.
    runner = load_script("mutation_test")
    report = tmp_path / "report.md"
    report.write_text("the last run's report\n")
    assert runner.main(["--report-only", "--report", str(report), "--results", str(tmp_path / "none.json")]) == 2
    assert report.read_text() == "the last run's report\n"
    assert "--report-only needs the results file of a run" in capsys.readouterr().err
