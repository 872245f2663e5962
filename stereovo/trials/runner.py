"""Run a grid's tasks on a backend, journal each finished trial, show progress with an ETA.

:func:`run_tasks` is what ``vo-gym baselines``, ``vo-gym evaluate`` and the library's
:func:`stereovo.benchmark.run_benchmark` share. Results come back keyed, so the caller puts
them in its canonical order: nothing depends on the backend, the worker count, the completion
order or on how many interrupts and resumes it took.
"""

from __future__ import annotations

import os
import signal
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

from stereovo.trials.backend import Backend, Task, chunked
from stereovo.trials.store import TrialJournal

__all__ = ["RunInterrupted", "RunResult", "run_tasks", "interrupted_message", "progress_bar", "sigterm_as_interrupt"]


class RunInterrupted(Exception):
    """Ctrl-C (or a dead local worker) stopped a run; ``saved`` of ``total`` trials are in the journal."""

    def __init__(self, saved: int, total: int, folder: Path | None, reason: str = "interrupted") -> None:
        super().__init__(reason)
        self.saved, self.total, self.folder, self.reason = saved, total, folder, reason

    def message(self) -> str:
        return interrupted_message(self.saved, self.total, self.folder, self.reason)


class sigterm_as_interrupt:
    """Within this block SIGTERM (a batch scheduler's or ``kill``'s stop) is handled like Ctrl-C.

    So a run stopped either way closes its journal and workers and says how to resume. Only in
    the main thread (signal handlers cannot be set elsewhere); elsewhere it does nothing.
    ``ray.init`` replaces the handler; :func:`stereovo.trials.backend.connect_ray` puts it back.
    """

    def __enter__(self) -> "sigterm_as_interrupt":
        import threading

        self._previous = None
        if threading.current_thread() is threading.main_thread():
            self._previous = signal.signal(signal.SIGTERM, self._raise)
        return self

    @staticmethod
    def _raise(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt

    def __exit__(self, *exc: Any) -> None:
        if self._previous is not None:
            signal.signal(signal.SIGTERM, self._previous)


def interrupted_message(saved: int, total: int, folder: Path | None, reason: str = "interrupted") -> str:
    """The one line a command prints when a run stops early."""
    where = f" in {folder}" if folder is not None else ""
    return f"{reason}: {saved} of {total} trials saved{where}; rerun with --resume"


@dataclass
class RunResult:
    """Every task's result by key, and what this call did."""

    results: dict[int, Any]
    computed: int  # tasks run by this call
    resumed: int  # tasks read back from the journal
    wall_s: float  # of this call


COMPILING_FORMAT = "{desc}: compiling the kernels (first run), {n_fmt}/{total_fmt} {unit} [{elapsed}]"
"""The bar while the kernels compile: elapsed time, no rate and no remaining-time estimate."""


def progress_bar(total: float, initial: float, desc: str, unit: str, enabled: bool, compiling: bool = False):
    """A tqdm bar on stderr with the remaining-time estimate (``compiling``: :data:`COMPILING_FORMAT`,
    without one); sparse updates when stderr is a file."""
    from tqdm.auto import tqdm

    interactive = hasattr(sys.stderr, "isatty") and sys.stderr.isatty()
    return tqdm(total=total, initial=initial, desc=desc, unit=unit, disable=not enabled, dynamic_ncols=True,
                mininterval=0.5 if interactive else 30.0, smoothing=0.05,
                bar_format=COMPILING_FORMAT if compiling else None)


def announce_once_for_workers() -> bool:
    """Print the compile notice here if kernels are not cached, and silence it in worker processes
    started from now on (they inherit :data:`stereovo.compilation.QUIET_ENV`), whatever they then
    compile: each would print its own line, after the run's first lines. Returns whether the
    kernels will compile."""
    from stereovo.compilation import QUIET_ENV, say_compiling, uncached_kernels

    compiling = bool(uncached_kernels())
    if compiling:
        say_compiling()
    os.environ[QUIET_ENV] = "1"
    return compiling


def _saved(journal: TrialJournal | None, results: dict[int, Any]) -> int:
    # Counted on disk: an interrupt may land between a trial's append and its bookkeeping here.
    return len(journal.read()) if journal is not None else len(results)


def run_tasks(
    fn: Callable[[Any], Any],
    tasks: Sequence[Task],
    backend: Backend,
    journal: TrialJournal | None = None,
    done: dict[int, Any] | None = None,
    warmup: Callable[[], None] | None = None,
    chunk: int = 1,
    progress: bool = True,
    desc: str = "trials",
    unit: str = "trial",
    rows_of: Callable[[Any], Sequence[dict]] = lambda r: r,
) -> RunResult:
    """Run the tasks not in ``done`` on ``backend``; append each finished one to ``journal``.

    Args:
        fn: ``payload -> result`` (picklable for process pools and Ray).
        tasks: keys must be unique.
        journal: an opened journal, or None (nothing is saved).
        done: results already in the journal (``TrialJournal.open``'s answer, which refuses a trial
            that is no task of the run when given the run's keys); not re-run.
        warmup: run once per worker process before its first trial (see :mod:`stereovo.trials.backend`).
        chunk: tasks per backend call.
        rows_of: the rows the journal stores for a result (identity: results are row lists).

    Raises:
        RunInterrupted: on Ctrl-C or a dead local worker; everything finished is in the journal.
    """
    keys = [t.key for t in tasks]
    if len(set(keys)) != len(keys):
        raise ValueError("task keys must be unique")
    results: dict[int, Any] = {k: v for k, v in (done or {}).items() if k in set(keys)}
    todo = [t for t in tasks if t.key not in results]
    weights = {t.key: t.weight for t in tasks}
    total_weight = sum(weights.values())
    # A first run compiles the kernels in every worker before its first trial: the bar says so instead
    # of an ETA that extrapolates the compile time, and the notice prints here, once for the run.
    compiling = bool(todo) and announce_once_for_workers()
    bar = progress_bar(total_weight, sum(weights[k] for k in results), desc, unit, progress, compiling=compiling)
    start = time.perf_counter()
    computed = 0
    folder = journal.folder if journal is not None else None
    try:
        for finished in backend.run(fn, chunked(todo, chunk), warmup):
            for key, result in finished:
                if journal is not None:
                    journal.append(key, rows_of(result))
                results[key] = result
                computed += 1
                bar.update(weights[key])
            if compiling:  # compiled: a fresh bar, whose rate and ETA start from here
                compiling = False
                bar.close()
                bar = progress_bar(total_weight, sum(weights[k] for k in results), desc, unit, progress)
    except KeyboardInterrupt:
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN)  # a second Ctrl-C must not cut the clean-up short
        try:
            bar.close()
            backend.close()
        finally:
            signal.signal(signal.SIGINT, previous)
        raise RunInterrupted(_saved(journal, results), len(tasks), folder) from None
    except Exception as err:
        from stereovo.trials.backend import WorkerDied

        if isinstance(err, WorkerDied):
            bar.close()
            raise RunInterrupted(_saved(journal, results), len(tasks), folder, reason=f"stopped ({err})") from None
        raise
    finally:
        bar.close()
    return RunResult(results, computed, len(tasks) - len(todo), time.perf_counter() - start)
