"""The ``vo-gym baselines`` command end to end, the report script, and the options a run would
ignore refused in one line."""

from __future__ import annotations

import csv
import importlib.util
import json
import re
from pathlib import Path

import pytest

from stereovo.benchmark import PLOT_FILES, TIME_COLUMNS, benchmark_methods
from tests.support.cli import exit_code, one_line_error
from vo_gym_cli.main import main

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


def test_the_hostile_outlier_kind_runs_beside_the_default_mix(tmp_path, capsys):
    argv = ["baselines", "--methods", "probabilistic", "--epsilons", "0.8", "--aucs", "0.75", "--ns", "200",
            "--frames-per-cell", "3", "--outlier-kinds", "mix,hostile", "--no-progress", "--no-plots",
            "--out", str(tmp_path / "run")]
    assert main(argv) == 0
    rows = _rows(tmp_path / "run" / "trials.csv")
    assert sorted(r["outlier_kind"] for r in rows) == ["hostile"] * 3 + ["mix"] * 3
    # the default method is right, or says it failed, on match errors it was not tuned on
    hostile = [r for r in rows if r["outlier_kind"] == "hostile"]
    assert all(r["success"] in ("True", "1") for r in hostile), hostile
    assert json.loads((tmp_path / "run" / "run.json").read_text())["grid_axes"]["outlier_kinds"] == ["mix", "hostile"]


def test_the_reports_command_line_parses_back_to_the_runs_grid():
    from stereovo.benchmark import DEFAULT_GRID
    from stereovo.benchmark.baseline_report import grid_flags
    from vo_gym_cli.main import build_parser

    axes = {**DEFAULT_GRID.as_dict(), "outlier_kinds": ["mix", "hostile"], "epsilons": [0.5, 0.85], "ns": [200],
            "score_aucs": [0.9], "noise_sigmas": [1.0], "frames_per_cell": 3, "max_iterations": 300, "preset": "free"}
    args = build_parser().parse_args(["baselines", *grid_flags({"grid_axes": axes}).split()])
    assert (args.epsilons, args.ns, args.aucs, args.sigmas, args.outlier_kinds, args.frames_per_cell,
            args.max_iterations, args.preset) == ([0.5, 0.85], [200], [0.9], [1.0], ["mix", "hostile"], 3, 300, "free")


def test_settings_the_simulator_cannot_draw_from_are_one_line_and_leave_out_as_it_was(tmp_path, capsys):
    argv = ["baselines", "--sigmas", "100", "--ns", "60", "--epsilons", "0.3", "--aucs", "0.9", "--frames-per-cell", "1",
            "--methods", "ransac", "--workers", "1", "--no-plots", "--no-progress", "--out", str(tmp_path / "x")]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "noise_sigma=100.0 px" in err[0] and "Traceback" not in err[0], err
    assert not (tmp_path / "x").exists()


def test_an_unknown_outlier_kind_is_one_line_naming_the_known_ones(tmp_path, capsys):
    code = main(["baselines", "--outlier-kinds", "mix,sky", "--out", str(tmp_path / "x"), "--no-progress"])
    assert code == 2
    err = capsys.readouterr().err
    assert "--outlier-kinds" in err and "'sky'" in err and "hostile" in err and "Traceback" not in err
    assert not (tmp_path / "x").exists()


def test_unknown_method_exits_nonzero_and_names_it(tmp_path, capsys):
    code = main(["baselines", "--methods", "ransac,bogosac", "--out", str(tmp_path / "x"), "--no-progress"])
    assert code != 0
    err = capsys.readouterr().err
    assert "bogosac" in err and "available" in err and "ransac" in err
    assert not (tmp_path / "x").exists()


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
    path = Path(__file__).resolve().parents[2] / "scripts" / "make_baseline_report.py"
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
    assert module.main(["--from", str(one), "--docs", str(docs), "--name", "baselines-full"]) == 0
    full = (docs / "baselines-full.md").read_text()
    assert "--from runs/baselines-full --name baselines-full" in full
    for name in PLOT_FILES:
        assert f"](img/baselines-full/{name})" in full and (docs / "img" / "baselines-full" / name).is_file()
    assert (docs / "baselines.md").read_text() == text  # the default report is left alone


# ------------------------------------------------------------------ results that survive


def _timeless(path: Path) -> list[dict[str, str]]:
    """A CSV's rows without its wall-time columns (``time_s``, ``*_time_ms``)."""
    return [{k: v for k, v in r.items() if "time" not in k} for r in _rows(path)]


def test_a_non_empty_out_is_refused_in_one_line(runs, capsys):
    one = runs[0]
    before = (one / "trials.csv").read_bytes()
    assert main(["baselines", *TINY, "--workers", "1", "--out", str(one)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "is not empty" in err[0] and "--resume" in err[0] and "--overwrite" in err[0]
    assert (one / "trials.csv").read_bytes() == before


def test_an_unwritable_out_is_refused_before_computing(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    assert main(["baselines", *TINY, "--out", str(blocker / "sub")]) == 2
    assert "--out" in capsys.readouterr().err


def test_interrupt_then_resume_writes_the_uninterrupted_files(runs, tmp_path, capsys, monkeypatch):
    from stereovo.benchmark import runner as bm  # run_benchmark looks run_trial up there

    one = runs[0]
    out = tmp_path / "run"
    real = bm.run_trial

    def stop_at_trial_3(trial, estimators, seed):
        if trial.index == 3:
            raise KeyboardInterrupt
        return real(trial, estimators, seed)

    monkeypatch.setattr(bm, "run_trial", stop_at_trial_3)
    capsys.readouterr()
    assert main(["baselines", *TINY, "--workers", "1", "--out", str(out)]) == 130
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"interrupted: 3 of 4 trials saved in {out}; rerun with --resume"]
    assert not (out / "trials.csv").exists()
    monkeypatch.setattr(bm, "run_trial", real)
    assert main(["baselines", *TINY, "--workers", "1", "--out", str(out), "--resume"]) == 0
    assert "resuming: 3 of 4 frames" in capsys.readouterr().out
    for name in ("trials.csv", "cells.csv", "summary.csv"):
        assert _timeless(out / name) == _timeless(one / name), name
    settings = json.loads((out / "run.json").read_text())
    assert settings["n_resumed"] == 3 and settings["n_trials"] == 4


def test_resume_with_other_settings_is_refused(runs, tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["baselines", *TINY, "--workers", "1", "--out", str(out), "--no-plots"]) == 0
    capsys.readouterr()
    assert main(["baselines", *TINY, "--seed", "12", "--out", str(out), "--resume"]) == 2
    assert "other settings (seed differ)" in capsys.readouterr().err


def test_report_only_rebuilds_tables_and_plots_from_the_stored_trials(runs, tmp_path, capsys):
    import shutil

    copy = tmp_path / "copy"
    shutil.copytree(runs[0], copy)
    for name in ("summary.csv", "cells.csv", "summary.md", "claims.md", *PLOT_FILES):
        (copy / name).unlink()
    assert main(["baselines", "--report-only", str(copy)]) == 0
    assert "rebuilt the report" in capsys.readouterr().out
    for name in ("summary.csv", "cells.csv"):
        assert _rows(copy / name) == _rows(runs[0] / name), name
    assert (copy / "summary.md").read_text() == (runs[0] / "summary.md").read_text()
    assert all((copy / name).stat().st_size > 0 for name in PLOT_FILES)
    assert main(["baselines", "--report-only", str(tmp_path / "nothing")]) == 2


@pytest.mark.parametrize("more, needle", [
    (["--methods", "msac"], "--methods msac applies to the simulated grid and --source rendered, not with --report-only"
                            " (it rebuilds the report of the run in DIR, in DIR, from the trials stored there)"),
    (["--out", "OTHER"], "--out OTHER applies to the simulated grid and --source rendered, not with --report-only"),
    (["--seed", "3"], "--seed 3 applies to the simulated grid and --source rendered, not with --report-only"),
    (["--source", "rendered"], "--report-only and --source rendered exclude each other: --report-only rebuilds"),
])
def test_report_only_refuses_what_it_would_ignore_and_writes_nothing(runs, tmp_path, capsys, more, needle):
    before = {p.name: p.stat().st_mtime_ns for p in runs[0].iterdir()}
    more = [str(tmp_path / "other") if m == "OTHER" else m for m in more]
    assert main(["baselines", "--report-only", str(runs[0]), *more]) == 2
    assert needle.replace("OTHER", str(tmp_path / "other")) in one_line_error(capsys, "baselines")
    assert {p.name: p.stat().st_mtime_ns for p in runs[0].iterdir()} == before
    assert not (tmp_path / "other").exists()


@pytest.mark.parametrize("more, needle", [
    (["--out", "runs/baselines"], "--out runs/baselines applies to the simulated grid and --source rendered, not with"
                                  " --report-only"),
    (["--seed", "0"], "--seed 0 applies to the simulated grid and --source rendered, not with --report-only"),
])
def test_report_only_refuses_an_option_typed_at_its_default(runs, tmp_path, capsys, monkeypatch, more, needle):
    monkeypatch.chdir(tmp_path)  # --out's default is relative
    before = {p.name: p.stat().st_mtime_ns for p in runs[0].iterdir()}
    assert main(["baselines", "--report-only", str(runs[0]), *more]) == 2
    assert needle in one_line_error(capsys, "baselines")
    assert {p.name: p.stat().st_mtime_ns for p in runs[0].iterdir()} == before
    assert not (tmp_path / "runs").exists()


@pytest.mark.parametrize("more, needle", [
    (["--resolution", "vga"], "--resolution vga applies to --source rendered, not to the simulated grid"),
    (["--frames", "5"], "--frames 5 applies to --source rendered, not to the simulated grid (the grid's frames are"
                        " --frames-per-cell)"),
    (["--source", "rendered", "--resume"], "--resume applies to the simulated grid, not with --source rendered (it"
                                           " keeps no journal to resume from; --overwrite replaces the run)"),
    (["--source", "rendered", "--epsilons", "0.5"], "--epsilons 0.5 applies to the simulated grid, not with --source"
                                                    " rendered"),
    (["--source", "rendered", "--workers", "2"], "--workers 2 applies to the simulated grid, not with --source rendered"
                                                 " (it runs in this process)"),
    (["--source", "rendered", "--backend", "local"], "--backend local applies to the simulated grid, not with --source"
                                                     " rendered (it runs in this process)"),  # typed at its default
    (["--source", "rendered:free", "--preset", "car"], "--preset car contradicts --source rendered:free"),
])
def test_an_option_the_run_would_ignore_is_refused_before_computing(tmp_path, capsys, more, needle):
    assert main(["baselines", *more, "--no-progress", "--out", str(tmp_path / "x")]) == 2
    assert needle in one_line_error(capsys, "baselines")
    assert not (tmp_path / "x").exists()


@pytest.mark.parametrize("flag, values, shown", [("--sigmas", "0", "got 0"), ("--sigmas", "1,-1.5", "got -1.5"),
                                                 ("--epsilons", "0.2,1.5", "got 1.5"), ("--ns", "80,2", "got 2")])
def test_an_axis_value_out_of_range_is_shown_as_given(tmp_path, capsys, flag, values, shown):
    assert main(["baselines", flag, values, "--out", str(tmp_path / "x")]) == 2
    line = one_line_error(capsys, "baselines")
    assert line.startswith(f"vo-gym baselines: error: {flag} must") and line.endswith(shown), line
    assert not (tmp_path / "x").exists()


def _start(argv: list[str], **popen):
    """The command ``vo-gym ARGV...`` as a child process, with SIGINT's default disposition.

    An xdist worker may ignore SIGINT, and a child inherits an ignored signal (Python then installs
    no KeyboardInterrupt handler): give the command the default disposition a terminal would.
    """
    import signal
    import subprocess
    import sys

    return subprocess.Popen([sys.executable, "-m", "vo_gym_cli", *argv], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL), **popen)


def _saved_trials(journal: Path) -> int:
    """Complete trials in a run's journal (a torn last block does not count)."""
    from stereovo.benchmark import parse_trial_value
    from stereovo.trials.store import read_journal

    return len(read_journal(journal, parse_trial_value))


def _wait_for_trials(proc, journal: Path, more_than: int) -> None:
    """Until the journal holds more than ``more_than`` trials, or the command ended."""
    import time

    deadline = time.monotonic() + 180  # only so that a hung command cannot hang the suite
    while time.monotonic() < deadline and proc.poll() is None and _saved_trials(journal) <= more_than:
        time.sleep(0.1)


@pytest.mark.parametrize("signame", ["SIGINT", "SIGTERM"])
def test_ctrl_c_or_sigterm_prints_one_line_and_exits_130(tmp_path, signame):
    import signal

    out = tmp_path / "run"
    # Trials of a few ms each, 3000 of them: the run cannot finish between the journal's first rows
    # and the signal (with 600 trials of under a millisecond it once did, on a busy machine).
    proc = _start(["baselines", "--methods", "ransac,msac", "--epsilons", "0.5,0.7,0.8", "--aucs", "0.9", "--ns", "300",
                   "--frames-per-cell", "1000", "--max-iterations", "2000", "--no-progress", "--no-plots",
                   "--workers", "2", "--out", str(out)])
    journal = out / "journal.csv"
    _wait_for_trials(proc, journal, 1)
    assert proc.poll() is None, "the run ended before it could be interrupted"
    proc.send_signal(getattr(signal, signame))
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    lines = err.strip().splitlines()
    assert "Traceback" not in err and len(lines) == 1, err
    saved = len({line.split(",")[0] for line in journal.read_text().splitlines()[1:]})
    assert lines[0] == f"interrupted: {saved} of 3000 trials saved in {out}; rerun with --resume"


# Trials of some 20-40 ms (N 1000 at eps 0.8): a few seconds of work on two workers, so a signal sent
# on the journal's first new trial always lands in the run, while resuming it stays quick.
RAY_GRID = ["--methods", "ransac,msac", "--epsilons", "0.8", "--aucs", "0.9", "--ns", "1000", "--frames-per-cell", "120",
            "--max-iterations", "2000", "--seed", "3", "--no-progress", "--no-plots"]


def _ray_processes(ray_tmp: str) -> list[str]:
    """Command lines of the live processes of the Ray instances started with ``RAY_TMPDIR=ray_tmp``.

    Ray's daemons and workers inherit the driver's environment; other Ray instances on the machine
    (another run's) have another RAY_TMPDIR and are not counted.
    """
    marker = f"RAY_TMPDIR={ray_tmp}".encode()
    found = []
    for proc in Path("/proc").iterdir():
        try:
            if proc.name.isdigit() and marker in (proc / "environ").read_bytes().split(b"\0"):
                found.append((proc / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace"))
        except OSError:  # gone meanwhile, or not ours to read
            continue
    return found


def _no_ray_left(ray_tmp: str) -> list[str]:
    import time

    deadline = time.monotonic() + 30  # ray.shutdown does not wait for its processes to be reaped
    while (left := _ray_processes(ray_tmp)) and time.monotonic() < deadline:
        time.sleep(0.2)
    return left


RAY_CORE_LOG = re.compile(r"^\[\d{4}-\d\d-\d\d [\d:,]+ [DIWEF] \d+ \d+\] \w+\.cc:\d+: ")


@pytest.mark.skipif(not Path("/proc/self/environ").is_file(), reason="finds Ray's processes through /proc")
def test_ray_backend_stops_on_sigterm_or_ctrl_c_in_one_line_and_resumes(tmp_path, capsys):
    """ray.init installs its own SIGTERM handlers (an exit, then a C++ dump and abort): ours must win.

    SIGTERM to the command alone (a scheduler's kill), then, on a resume, SIGINT to its process
    group (Ctrl-C in a terminal: Ray's daemons get it too); a last resume (local: the journal does
    not depend on the backend) completes the run with the files an uninterrupted run writes.
    """
    pytest.importorskip("ray")
    import os
    import shutil
    import signal
    import tempfile

    from stereovo.compilation import MESSAGE

    out, total = tmp_path / "run", 120
    journal = out / "journal.csv"
    # A short folder of its own (Ray's socket paths are length-limited): it tells our Ray processes
    # from any other instance's.
    ray_tmp = tempfile.mkdtemp(prefix="vo-ray-", dir="/tmp")
    env = dict(os.environ, RAY_TMPDIR=ray_tmp)
    argv = ["baselines", *RAY_GRID, "--out", str(out)]
    proc = None
    try:
        saved = 0
        for signame, to_group in (("SIGTERM", False), ("SIGINT", True)):
            proc = _start(argv + ["--backend", "ray", "--workers", "2"] + (["--resume"] if saved else []), env=env,
                          start_new_session=True)
            _wait_for_trials(proc, journal, saved)
            assert proc.poll() is None, "the run ended before it could be interrupted"
            sig = getattr(signal, signame)
            os.killpg(proc.pid, sig) if to_group else proc.send_signal(sig)
            _, err = proc.communicate(timeout=120)
            where = f"{signame} to the {'process group' if to_group else 'command'}"
            assert proc.returncode == 130, (where, err)
            # The workers' first-run line (numba compiling, forwarded by Ray) is the only other output
            # allowed, besides Ray's own C++ core log lines ("[date time E pid tid] file.cc:line: ..."),
            # which a loaded machine can get at teardown (a worker's error that can no longer reach the
            # driver it is being killed with) and which no setting of ours writes.
            lines = [line for line in err.splitlines()
                     if line.strip() and MESSAGE not in line and not RAY_CORE_LOG.match(line)]
            now = _saved_trials(journal)
            assert lines == [f"interrupted: {now} of {total} trials saved in {out}; rerun with --resume"], (where, err)
            assert saved < now < total, where  # the earlier trials kept, this run's added
            assert not _no_ray_left(ray_tmp), where
            saved = now
    finally:
        if proc is not None and proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
        _no_ray_left(ray_tmp)  # a Ray process still exiting would write its logs back after the removal
        shutil.rmtree(ray_tmp, ignore_errors=True)
    reference = tmp_path / "reference"
    assert main(["baselines", *RAY_GRID, "--workers", "1", "--out", str(reference)]) == 0
    capsys.readouterr()
    assert main(argv + ["--workers", "1", "--resume"]) == 0
    assert f"resuming: {saved} of {total} frames" in capsys.readouterr().out
    for name in ("trials.csv", "cells.csv", "summary.csv"):
        assert _timeless(out / name) == _timeless(reference / name), name


# --- baselines --source rendered: the classical family on rendered stereo images ---

def test_baselines_on_rendered_images_writes_rows_summary_and_plot_and_repeats_bit_for_bit(tmp_path, capsys, short):
    argv = ["baselines", "--source", "rendered", "--resolution", "vga", "--frames", "3", "--seed", "4",
            "--methods", "ransac,probabilistic", "--no-progress"]
    assert main([*argv, "--out", str(tmp_path / "a")]) == 0
    printed = capsys.readouterr().out
    assert "2 methods on 3 rendered pairs (car, vga, seed 4)" in printed and "| probabilistic | 3 |" in printed
    for name in ("frames.csv", "summary.json", "summary.md", "success_vs_time.png"):
        assert (tmp_path / "a" / name).stat().st_size > 0, name
    rows = _rows(tmp_path / "a" / "frames.csv")
    assert [(r["frame"], r["method"]) for r in rows] == [(str(k), m) for k in (1, 2, 3) for m in ("ransac", "probabilistic")]
    # the rendered pairs of seed 4 are easy: both methods within 1 deg / 5 cm of the true motion
    assert all(r["success"] == "True" and float(r["rot_err_deg"]) < 1.0 for r in rows)
    assert all(0.0 <= float(r["outlier_ratio"]) < 1.0 and int(r["n"]) == int(short.frame(int(r["frame"])).n) for r in rows)
    summary = json.loads((tmp_path / "a" / "summary.json").read_text())
    assert summary["settings"]["frames"] == 3 and [s["method"] for s in summary["summary"]] == ["ransac", "probabilistic"]
    assert all(s["success"] == 1.0 and s["ci_low"] < 1.0 for s in summary["summary"])
    # same seed, same rows (wall time aside), whatever the order of the methods
    assert main([*argv[:-2], "probabilistic,ransac", "--no-progress", "--no-plots", "--out", str(tmp_path / "b")]) == 0
    again = {(r["frame"], r["method"]): r for r in _without_time(_rows(tmp_path / "b" / "frames.csv"))}
    assert {(r["frame"], r["method"]): r for r in _without_time(rows)} == again
    assert not (tmp_path / "b" / "success_vs_time.png").exists()


@pytest.mark.parametrize("argv, needle", [
    (["--source", "kitti:/nowhere"], "baselines needs per-match ground truth"),
    (["--source", "rendered:plane"], "the rendered preset must be one of car, free, got 'plane'"),
    (["--source", "rendered", "--methods", "nosac"], "--methods: unknown method(s): nosac"),
    (["--source", "rendered", "--frames", "0"], "--frames must be >= 1"),
])
def test_baselines_on_images_refuses_what_it_cannot_run_in_one_line(tmp_path, capsys, argv, needle):
    assert exit_code(["baselines", *argv, "--no-progress", "--out", str(tmp_path / "x")]) == 2
    assert needle in one_line_error(capsys, "baselines")
    assert not (tmp_path / "x").exists()


def test_baselines_on_images_replaces_a_non_empty_out_only_with_overwrite(tmp_path, capsys, short):
    argv = ["baselines", "--source", "rendered", "--resolution", "vga", "--frames", "1", "--seed", "4",
            "--no-progress", "--no-plots", "--out", str(tmp_path / "a")]
    assert main([*argv, "--methods", "msac"]) == 0
    capsys.readouterr()
    assert main([*argv, "--methods", "ransac"]) == 2
    assert "is not empty; pass --overwrite to replace the run there" in one_line_error(capsys, "baselines")
    assert {r["method"] for r in _rows(tmp_path / "a" / "frames.csv")} == {"msac"}
    assert main([*argv, "--methods", "ransac", "--overwrite"]) == 0
    assert {r["method"] for r in _rows(tmp_path / "a" / "frames.csv")} == {"ransac"}


def _folder_bytes(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if p.is_file()}


@pytest.mark.parametrize("name, content, needle", [
    ("run.json", b"{bad", "run.json"),
    ("run.json", b"[1]", "run.json"),
    ("trials.csv", b"\xff\xfe\x80garbage", "trials.csv"),
    ("trials.csv", None, "trials.csv"),  # a number column holding text
])
def test_report_only_on_a_corrupt_file_is_one_line_and_leaves_the_folder_byte_for_byte(runs, tmp_path, capsys,
                                                                                       name, content, needle):
    # they were tracebacks, after trials.csv, summary.csv and cells.csv had been rewritten
    import shutil

    copy = tmp_path / "copy"
    shutil.copytree(runs[0], copy)
    if name == "trials.csv":  # a folder of results alone (as a published grid's): its trials are the source
        (copy / "journal.csv").unlink()
        (copy / "manifest.json").unlink()
    if content is None:
        text = (copy / name).read_text().splitlines()
        columns = text[0].split(",")
        cells = text[1].split(",")
        cells[columns.index("rot_err_deg")] = "hello"
        content = "\n".join([text[0], ",".join(cells), *text[2:]]).encode() + b"\n"
    (copy / name).write_bytes(content)
    before = _folder_bytes(copy)
    assert main(["baselines", "--report-only", str(copy)]) == 2
    line = one_line_error(capsys, "baselines")
    assert "--report-only" in line and needle in line, line
    assert _folder_bytes(copy) == before


@pytest.mark.parametrize("name, content", [("manifest.json", b"[1, 2, 3]"), ("manifest.json", b"{not json"),
                                           ("journal.csv", b"\xff\xfe\x80")])
def test_resume_on_a_corrupt_run_folder_is_one_line_naming_the_file(tmp_path, capsys, name, content):
    out = tmp_path / "run"
    assert main(["baselines", *TINY, "--out", str(out), "--no-plots"]) == 0
    target = out / name
    target.write_bytes(content if name == "manifest.json" else target.read_bytes() + content)
    capsys.readouterr()
    assert main(["baselines", *TINY, "--out", str(out), "--no-plots", "--resume"]) == 2
    line = one_line_error(capsys, "baselines")
    assert name in line, line
