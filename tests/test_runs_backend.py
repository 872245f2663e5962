"""stereovo.trials: the journal survives crashes, resume runs only what is missing, and the rows
never depend on the backend (local pool or Ray), the worker count, or a worker killed mid-run."""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from stereovo import benchmark as bm
from stereovo.trials import (
    LocalBackend,
    RunFolderError,
    RunInterrupted,
    Task,
    TrialJournal,
    make_backend,
    prepare_run_folder,
    run_tasks,
)
from stereovo.trials.store import JOURNAL

GRID = bm.BenchmarkGrid(epsilons=(0.2, 0.6), noise_sigmas=(0.5,), score_aucs=(0.9,), ns=(60,), frames_per_cell=3,
                        max_iterations=200)
METHODS = ("ransac", "msac")


def _without_time(rows):
    return [{k: v for k, v in r.items() if k not in bm.TIME_COLUMNS} for r in rows]


def _same(a, b):
    """Row lists equal, NaN equal to NaN."""
    assert len(a) == len(b)
    for x, y in zip(a, b):
        assert x.keys() == y.keys()
        for k in x:
            if isinstance(x[k], float) and math.isnan(x[k]):
                assert isinstance(y[k], float) and math.isnan(y[k]), k
            else:
                assert x[k] == y[k], (k, x[k], y[k])


def _estimators():
    return bm.classical_estimators(list(METHODS), max_iterations=GRID.max_iterations)


@pytest.fixture(scope="module")
def reference():
    """The grid's rows in this process (one local worker)."""
    return bm.run_benchmark(GRID.trials(), _estimators(), seed=5, workers=1, progress=False)


# ------------------------------------------------------------------ journal


def _journal(folder: Path) -> TrialJournal:
    return TrialJournal(folder, bm.TRIAL_COLUMNS, bm.parse_trial_value)


def test_journal_round_trips_rows_bit_for_bit(tmp_path, reference):
    journal = _journal(tmp_path)
    assert journal.open({"run": 1}, resume=False) == {}
    by_trial = {}
    for row in reference:
        by_trial.setdefault(row["trial"], []).append(row)
    for key, rows in by_trial.items():
        journal.append(key, rows)
    journal.close()
    back = journal.read()
    assert sorted(back) == sorted(by_trial)
    _same([r for k in sorted(back) for r in back[k]], reference)  # floats via repr: exact


def test_a_torn_block_is_dropped_and_the_rest_kept(tmp_path, reference):
    journal = _journal(tmp_path)
    journal.open({"run": 1}, resume=False)
    journal.append(0, reference[0:2])
    journal.append(1, reference[2:4])
    journal.close()
    text = (tmp_path / JOURNAL).read_text()
    lines = text.splitlines(keepends=True)
    # A crash in the middle of trial 1's block: its second row is missing and the first is torn.
    (tmp_path / JOURNAL).write_text("".join(lines[:-2]) + lines[-2][: len(lines[-2]) // 2])
    assert sorted(journal.read()) == [0]
    done = _journal(tmp_path).open({"run": 1}, resume=True)
    assert sorted(done) == [0]
    assert (tmp_path / JOURNAL).read_text() == "".join(lines[:-2])  # rewritten with whole blocks only


def test_resume_refuses_a_folder_with_other_settings(tmp_path):
    _journal(tmp_path).open({"seed": 1, "methods": ["ransac"]}, resume=False)
    with pytest.raises(RunFolderError, match="other settings.*seed"):
        _journal(tmp_path).open({"seed": 2, "methods": ["ransac"]}, resume=True)


def test_a_non_empty_folder_is_refused_unless_resume_or_overwrite(tmp_path):
    (tmp_path / "old.txt").write_text("x")
    with pytest.raises(RunFolderError, match="not empty.*--resume.*--overwrite"):
        prepare_run_folder(tmp_path, resume=False, overwrite=False)
    prepare_run_folder(tmp_path, resume=True, overwrite=False)
    (tmp_path / JOURNAL).write_text("task\n")
    prepare_run_folder(tmp_path, resume=False, overwrite=True)
    assert not (tmp_path / JOURNAL).exists()
    with pytest.raises(RunFolderError, match="exclude"):
        prepare_run_folder(tmp_path, resume=True, overwrite=True)


# ------------------------------------------------------------------ local backend


def _square(x):
    return [{"x": x, "y": x * x}]


class _StopAt:
    """Raises KeyboardInterrupt at payload ``at`` (Ctrl-C in the middle of a run)."""

    def __init__(self, at):
        self.at = at

    def __call__(self, x):
        if x == self.at:
            raise KeyboardInterrupt
        return _square(x)


def test_interrupt_keeps_the_finished_trials_and_resume_runs_only_the_rest(tmp_path):
    tasks = [Task(i, i) for i in range(8)]
    parse = lambda c, t: int(t)  # noqa: E731
    journal = TrialJournal(tmp_path, ("x", "y"), parse)
    journal.open({"n": 8}, resume=False)
    with pytest.raises(RunInterrupted) as stop:
        run_tasks(_StopAt(5), tasks, LocalBackend(1), journal, progress=False)
    journal.close()
    assert (stop.value.saved, stop.value.total) == (5, 8)
    assert stop.value.message() == f"interrupted: 5 of 8 trials saved in {tmp_path}; rerun with --resume"
    journal = TrialJournal(tmp_path, ("x", "y"), parse)
    done = journal.open({"n": 8}, resume=True)
    assert sorted(done) == [0, 1, 2, 3, 4]
    seen = []

    def counting(x):
        seen.append(x)
        return _square(x)

    result = run_tasks(counting, tasks, LocalBackend(1), journal, done=done, progress=False)
    journal.close()
    assert seen == [5, 6, 7] and result.computed == 3 and result.resumed == 5
    assert journal.read() == {i: [{"x": i, "y": i * i}] for i in range(8)}


def test_local_pool_gives_the_same_rows_as_one_process(reference):
    rows = bm.run_benchmark(GRID.trials(), _estimators(), seed=5, workers=2, progress=False, chunk=2)
    _same(_without_time(rows), _without_time(reference))


def test_address_needs_ray_and_unknown_backends_are_named():
    with pytest.raises(ValueError, match="--address.*--backend ray"):
        make_backend("local", 1, "auto")
    with pytest.raises(ValueError, match="unknown backend 'dask'"):
        make_backend("dask", 1)


def test_importing_the_packages_starts_neither_ray_nor_torch():
    code = "import sys, stereovo, vo_gym, stereovo.trials, stereovo.benchmark; print('ray' in sys.modules, 'torch' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert out == ["False", "False"]


# ------------------------------------------------------------------ Ray


@pytest.fixture(scope="module")
def ray_backend():
    pytest.importorskip("ray")
    import ray

    backend = make_backend("ray", 2)
    # Test-module callables travel by value: Ray's workers need not import this file.
    ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])
    yield backend
    backend.close()
    assert not ray.is_initialized()


class KillOnce:
    """An estimator that kills its own worker process the first time it sees trial ``victim``'s frame.

    The marker file tells a retried attempt that the kill already happened.
    """

    def __init__(self, inner, victim_t_norm, marker):
        self.inner, self.victim_t_norm, self.marker = inner, victim_t_norm, marker

    def __call__(self, frame, rng):
        t_norm = float(np.linalg.norm(frame.truth.translation))
        if math.isclose(t_norm, self.victim_t_norm, rel_tol=1e-12) and not os.path.exists(self.marker):
            Path(self.marker).write_text(str(os.getpid()))
            os.kill(os.getpid(), signal.SIGKILL)
        return self.inner(frame, rng)


def test_ray_gives_the_same_rows_as_one_local_process(ray_backend, reference):
    rows = bm.run_benchmark(GRID.trials(), _estimators(), seed=5, progress=False, backend=ray_backend)
    _same(_without_time(rows), _without_time(reference))


def _niceness(_):
    return os.nice(0)


def test_ray_workers_run_at_the_callers_niceness(ray_backend):
    """Not Ray's default 15: on a busy machine that starves the trials (0.69x one local worker, measured)."""
    from stereovo.trials import Task, run_tasks

    result = run_tasks(_niceness, [Task(i, i) for i in range(4)], ray_backend, progress=False)
    assert set(result.results.values()) == {os.nice(0)}


def test_ray_retries_a_trial_whose_worker_was_killed(ray_backend, reference, tmp_path):
    victim = [r for r in reference if r["trial"] == 4][0]["t_true_norm_m"]
    assert sum(math.isclose(r["t_true_norm_m"], victim, rel_tol=1e-12) for r in reference if r["method"] == "ransac") == 1
    marker = tmp_path / "killed"
    estimators = [(name, KillOnce(est, victim, str(marker)) if name == "ransac" else est)
                  for name, est in _estimators()]
    journal = _journal(tmp_path / "run")
    (tmp_path / "run").mkdir()
    journal.open({"kill": 1}, resume=False)
    rows = bm.run_benchmark(GRID.trials(), estimators, seed=5, progress=False, backend=ray_backend, journal=journal,
                            warmup=False)
    journal.close()
    assert marker.is_file()  # a worker really died, in the middle of the run
    _same(_without_time(rows), _without_time(reference))
    stored = journal.read()
    _same(_without_time([r for k in sorted(stored) for r in stored[k]]), _without_time(reference))
