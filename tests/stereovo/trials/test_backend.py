"""stereovo.trials backends and runner: resume runs only what is missing, and the rows never depend
on the backend (local pool or Ray), the worker count, or a worker killed mid-run."""

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
from stereovo.trials import LocalBackend, RunInterrupted, Task, TrialJournal, make_backend, run_tasks
from tests.support.benchmark import same_rows
from tests.support.trials import GRID, open_journal, trial_estimators


def _without_time(rows):
    return [{k: v for k, v in r.items() if k not in bm.TIME_COLUMNS} for r in rows]


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


def _niceness(_):
    return os.nice(0)


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
    rows = bm.run_benchmark(GRID.trials(), trial_estimators(), seed=5, workers=2, progress=False, chunk=2)
    same_rows(_without_time(rows), _without_time(reference))


def test_address_needs_ray_and_unknown_backends_are_named():
    with pytest.raises(ValueError, match="--address.*--backend ray"):
        make_backend("local", 1, "auto")
    with pytest.raises(ValueError, match="unknown backend 'dask'"):
        make_backend("dask", 1)


def test_importing_the_packages_starts_neither_ray_nor_torch():
    code = "import sys, stereovo, vo_gym, stereovo.trials, stereovo.benchmark; print('ray' in sys.modules, 'torch' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert out == ["False", "False"]


def test_ray_gives_the_same_rows_as_one_local_process(ray_backend, reference):
    rows = bm.run_benchmark(GRID.trials(), trial_estimators(), seed=5, progress=False, backend=ray_backend)
    same_rows(_without_time(rows), _without_time(reference))


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
                  for name, est in trial_estimators()]
    journal = open_journal(tmp_path / "run")
    (tmp_path / "run").mkdir()
    journal.open({"kill": 1}, resume=False)
    rows = bm.run_benchmark(GRID.trials(), estimators, seed=5, progress=False, backend=ray_backend, journal=journal,
                            warmup=False)
    journal.close()
    assert marker.is_file()  # a worker really died, in the middle of the run
    same_rows(_without_time(rows), _without_time(reference))
    stored = journal.read()
    same_rows(_without_time([r for k in sorted(stored) for r in stored[k]]), _without_time(reference))
