"""The estimators of a benchmark run and the runner that puts every one on every trial's frame.

An *estimator* is any picklable callable ``(frame, rng) -> estimate`` where the estimate has
the fields of :class:`stereovo.estimation.MotionEstimate` that
:func:`stereovo.metrics.frame_metrics` reads. :class:`ClassicalEstimator` wraps a registered
method (:func:`classical_estimators` builds them by name, guided variants included); a learned
agent is just another callable.

:func:`run_benchmark` simulates each trial's frame once, runs every estimator on it and records
one row per (trial, estimator) with the columns :data:`TRIAL_COLUMNS`. Wall time
(``time_s``, :data:`TIME_COLUMNS`) is the only column that differs between two runs with one
seed; worker count and completion order do not change any row. The functions a backend sends
to worker processes (:func:`run_trial`, :func:`warm_up_estimators`) are module-level, so they
pickle by name.
"""

from __future__ import annotations

import math
import os
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass
from functools import partial
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from stereovo.benchmark.grid import GridCell, Trial, check_seed, estimator_seed, simulate_trial
from stereovo.estimation import available_methods, drop_unread, estimate_motion
from stereovo.metrics import frame_metrics
from stereovo.simulation import Frame, simulate_frame
from stereovo.options import Integer

Estimator = Callable[[Frame, np.random.Generator], Any]
"""``(frame, rng) -> estimate`` with the fields :func:`stereovo.metrics.frame_metrics` reads."""

METHOD_INPUTS: dict[str, str] = {
    "guided-mlesac": "probabilities",
    "prosac": "order",
    "usac": "order",
}
"""Registered methods that need the match scores, and how: ``probabilities`` = the scores as
calibrated inlier probabilities (:attr:`~stereovo.simulation.Frame.match_probabilities`:
Guided-MLESAC's gamma_i is the chance that a match is correct, which a raw score is not),
``order`` = ``argsort(-scores)`` (best match first)."""

GUIDED_VARIANTS: dict[str, tuple[str, str]] = {
    "ransac+guided": ("ransac", "priors"),
    "ransac+prosac-order": ("ransac", "order"),
    "probabilistic+guided": ("probabilistic", "priors"),
    "bansac+guided": ("bansac", "priors"),
    "ars+guided": ("ars", "priors"),
}
"""Extra benchmark entries: a registered method run with the match scores as
sampling priors (guided sampling) or as a PROSAC order, everything else unchanged."""

_INPUT_KINDS = ("priors", "probabilities", "order")


def _missing_input(err: ValueError) -> str | None:
    """Which input a method's ValueError asks for, if it is about a missing prior/order."""
    text = str(err).lower()
    if "prior" in text:
        return "priors"
    if "order" in text:
        return "order"
    return None


def score_inputs(frame: Frame, kind: str | None) -> dict[str, np.ndarray]:
    """The keyword arguments that hand a frame's match scores to ``estimate_motion``: as sampling
    weights (``priors``), as calibrated inlier probabilities (``probabilities``, passed as priors)
    or as a PROSAC order (``order``)."""
    if kind is None:
        return {}
    if kind == "priors":
        return {"priors": np.asarray(frame.scores, dtype=float)}
    if kind == "probabilities":
        return {"priors": frame.match_probabilities}
    if kind == "order":
        return {"order": np.argsort(-np.asarray(frame.scores, dtype=float), kind="stable")}
    raise ValueError(f"unknown score input {kind!r}; expected one of {_INPUT_KINDS}")


@dataclass(frozen=True)
class ClassicalEstimator:
    """A registered method as a benchmark estimator (picklable, for process pools).

    Args:
        method: a name from :func:`stereovo.estimation.available_methods`.
        inputs: None, ``"priors"``, ``"probabilities"`` or ``"order"``: how the frame's match scores
            are passed (:func:`score_inputs`).
            With None, a method that raises ``ValueError`` naming priors or order is
            retried once with that input, in the form :data:`METHOD_INPUTS` declares for it (same
            random stream).
        options: ``estimate_motion`` options as ``(name, value)`` pairs; the frame's
            ``noise_sigma`` is always passed.
    """

    method: str
    inputs: str | None = None
    options: tuple[tuple[str, Any], ...] = ()

    def __post_init__(self) -> None:
        if self.inputs is not None and self.inputs not in _INPUT_KINDS:
            raise ValueError(f"inputs must be None or one of {_INPUT_KINDS}, got {self.inputs!r}")

    def _estimate(self, frame: Frame, rng: np.random.Generator, inputs: str | None):
        return estimate_motion(
            frame.prev, frame.curr, frame.camera, method=self.method, rng=rng,
            noise_sigma=frame.noise_sigma, **score_inputs(frame, inputs), **dict(self.options),
        )

    def __call__(self, frame: Frame, rng: np.random.Generator):
        state = rng.bit_generator.state
        try:
            return self._estimate(frame, rng, self.inputs)
        except ValueError as err:
            needed = _missing_input(err) if self.inputs is None else None
            if needed is None:
                raise
            needed = METHOD_INPUTS.get(self.method, needed)  # its declared form: guided MLESAC's calibrated priors
            rng.bit_generator.state = state
            return self._estimate(frame, rng, needed)


def benchmark_methods() -> list[str]:
    """Every name ``vo-gym baselines`` can run: registered methods, then the guided variants."""
    registered = list(available_methods())
    return registered + [v for v, (base, _) in GUIDED_VARIANTS.items() if base in registered]


def describe_method(name: str) -> str:
    """One line for the report: the method's description, its recipe (the paper's, or the enhancements
    it switches on) and its reference; for a guided variant, how the match scores are passed."""
    if name in GUIDED_VARIANTS:
        base, kind = GUIDED_VARIANTS[name]
        how = "sampling weights (guided sampling)" if kind == "priors" else "PROSAC sampling order"
        return f"{base} with the match scores as {how}"
    description = available_methods().get(name, "")
    kind = METHOD_INPUTS.get(name)
    passed = {"probabilities": "priors, calibrated to inlier probabilities"}.get(kind, kind)
    return description + (f"; match scores passed as {passed}" if kind else "")


def classical_estimators(
    names: Sequence[str] | None = None, **options: Any
) -> list[tuple[str, ClassicalEstimator]]:
    """``(name, estimator)`` pairs for registered methods and guided variants.

    Args:
        names: names from :func:`benchmark_methods`; None runs all of them.
        **options: ``estimate_motion`` options for every method (e.g. ``max_iterations``): each method
            gets those it reads (:func:`stereovo.estimation.drop_unread`; ``preemptive`` draws its own M
            hypotheses under no ``max_iterations``, ``inlier-detection`` none), which it would refuse.

    Raises:
        ValueError: naming the unknown methods and listing the known ones.
    """
    known = benchmark_methods()
    names = list(known) if names is None else list(dict.fromkeys(names))
    unknown = [n for n in names if n not in known]
    if unknown:
        raise ValueError(f"unknown method(s): {', '.join(unknown)}; available: {', '.join(known)}")
    if not names:
        raise ValueError("no methods selected")
    out = []
    for name in names:
        base, kind = GUIDED_VARIANTS.get(name, (name, METHOD_INPUTS.get(name)))
        out.append((name, ClassicalEstimator(base, kind, tuple(sorted(_options_read(base, kind, options).items())))))
    return out


def _options_read(method: str, kind: str | None, options: dict[str, Any]) -> dict[str, Any]:
    """Those of ``options`` that ``method`` reads with the score input ``kind``; all of them where
    they are invalid, so that each estimate records the error as it did."""
    try:
        return drop_unread(method, options, order=kind == "order" if kind is not None else None)
    except ValueError:
        return options


TIME_COLUMNS: tuple[str, ...] = ("time_s",)
"""Columns that differ between two runs with one seed (wall time); everything else is bit-identical."""

TRIAL_COLUMNS: tuple[str, ...] = (
    "trial", "cell", "repeat", "epsilon", "noise_sigma", "score_auc", "n", "outlier_kind", "method",
    "success", "rot_err_deg", "trans_err_m", "t_true_norm_m", "precision", "recall", "n_inliers",
    "n_true_inliers", "n_hypotheses", "n_hypotheses_to_best", "n_scored", "n_point_checks", "status", "time_s",
)


def measure_estimator(estimator: Estimator, frame: Frame, rng: np.random.Generator) -> tuple[dict[str, Any], float]:
    """Run one estimator on one frame: its frame metrics (no wall time) and the wall time in seconds.

    An estimator that raises is recorded, not propagated: ``status = "error: <type>: <message>"``,
    NaN errors and ``success = False``. ``n_hypotheses_to_best`` is the loop report's
    ``best_found_at`` (NaN for estimators without one).
    """
    start = time.perf_counter()
    try:
        estimate = estimator(frame, rng)
    except Exception as err:  # noqa: BLE001 - recorded, counted and reported by the caller
        elapsed = time.perf_counter() - start
        message = " ".join(str(err).split())[:200]
        return {
            "success": False, "rot_err_deg": math.nan, "trans_err_m": math.nan,
            "t_true_norm_m": float(np.linalg.norm(frame.truth.translation)),
            "precision": math.nan, "recall": math.nan, "n_inliers": 0, "n_hypotheses": 0,
            "n_scored": 0, "n_point_checks": 0, "status": f"error: {type(err).__name__}: {message}",
            "n_hypotheses_to_best": math.nan,
        }, elapsed
    elapsed = time.perf_counter() - start
    metrics = frame_metrics(estimate, frame.truth).as_dict()
    metrics.pop("time_s")
    found_at = getattr(getattr(estimate, "report", None), "best_found_at", None)
    metrics["n_hypotheses_to_best"] = math.nan if found_at is None else float(found_at)
    return metrics, elapsed


def run_trial(trial: Trial, estimators: Sequence[tuple[str, Estimator]], seed: int) -> list[dict[str, Any]]:
    """Simulate the trial's frame once and run every estimator on it: one row per estimator.

    Columns as :func:`measure_estimator`; ``time_s`` is the wall time of the whole
    estimator call (for a learned agent it includes the network).
    """
    frame = simulate_trial(trial, seed)
    base = {"trial": trial.index, "cell": trial.cell_index, "repeat": trial.repeat, **trial.cell.as_dict()}
    n_true = int(np.count_nonzero(frame.truth.inlier))
    rows = []
    for name, estimator in estimators:
        rng = np.random.default_rng(estimator_seed(seed, trial.cell, trial.repeat, name))
        metrics, elapsed = measure_estimator(estimator, frame, rng)
        row = {**base, "method": name, **metrics, "n_true_inliers": n_true, "time_s": elapsed}
        rows.append({column: row[column] for column in TRIAL_COLUMNS})
    return rows


def default_workers() -> int:
    """The CPUs this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def ordered_map(
    fn: Callable[[Any], Any],
    jobs: Sequence[Any],
    workers: int,
    bar: Any,
    weights: Sequence[float] | None = None,
    initializer: Callable[[], None] | None = None,
) -> list[Any]:
    """``[fn(job) for job in jobs]`` in this process (``workers == 1``) or in a process pool.

    Results come back in job order either way, so nothing downstream depends on the worker
    count or on completion order. ``bar`` (a tqdm bar) advances by each job's weight (1 by
    default) as the job finishes; a failure cancels the jobs that have not started and is
    re-raised. ``fn`` must be picklable for ``workers > 1``.
    """
    jobs = list(jobs)
    weights = [1] * len(jobs) if weights is None else list(weights)
    results: list[Any] = [None] * len(jobs)
    if workers == 1 or len(jobs) <= 1:
        for i, job in enumerate(jobs):
            results[i] = fn(job)
            bar.update(weights[i])
        return results
    with ProcessPoolExecutor(max_workers=min(int(workers), len(jobs)), initializer=initializer) as pool:
        pending = {pool.submit(fn, job): i for i, job in enumerate(jobs)}
        try:
            while pending:
                done, _ = wait(pending, return_when=FIRST_COMPLETED)
                for future in done:
                    i = pending.pop(future)
                    results[i] = future.result()
                    bar.update(weights[i])
        except BaseException:
            for future in pending:
                future.cancel()
            raise
    return results


def warm_up_estimators(estimators: Sequence[tuple[str, Estimator]]) -> None:
    """Run every estimator once on a small frame, so numba compiles (or loads its cache) outside any timing.

    A backend runs this once per worker process before its first trial. Errors are ignored:
    the real trial records them.
    """
    cell = GridCell(0.3, 0.5, 0.9, 60)
    frame = simulate_frame(cell.config(), np.random.default_rng(0))
    for _, estimator in estimators:
        try:
            estimator(frame, np.random.default_rng(0))
        except Exception:  # noqa: BLE001 - recorded by the trial itself
            pass


def run_benchmark(
    trials: Sequence[Trial],
    estimators: Sequence[tuple[str, Estimator]],
    seed: int = 0,
    workers: int = 1,
    progress: bool = True,
    desc: str = "benchmark",
    backend: Any = None,
    journal: Any = None,
    done: Mapping[int, list[dict[str, Any]]] | None = None,
    warmup: bool = True,
    chunk: int = 1,
) -> list[dict[str, Any]]:
    """Run every estimator on every trial's frame; rows in trial order, then estimator order.

    Args:
        trials: e.g. ``grid.trials()``; ``Trial.index`` is the trial's key and must be unique.
        estimators: ``(name, callable)`` pairs; names must be unique. Off this process
            the callables must be picklable (module-level classes/functions, ``functools.partial``).
        seed: base seed (an integer >= 0).
        workers: processes of the default local backend; 1 runs in this process. The rows do not
            depend on it.
        progress: show a tqdm bar (stderr) with the remaining-time estimate, one step per frame.
        backend: a :class:`stereovo.trials.Backend` (None: a local one with ``workers``, closed at
            the end). The rows do not depend on it.
        journal: an opened :class:`stereovo.trials.TrialJournal`: each finished trial is appended
            to it at once (None: nothing is saved until the caller writes the rows).
        done: rows of trials already in the journal, by trial index; they are not re-run.
        warmup: run every estimator once per worker process before timing anything.
        chunk: trials per backend call.

    Raises:
        stereovo.trials.RunInterrupted: Ctrl-C; every finished trial is in ``journal``.
    """
    from stereovo.trials import Task, make_backend, run_tasks

    seed = check_seed(seed)
    names = [name for name, _ in estimators]
    if len(set(names)) != len(names):
        raise ValueError(f"estimator names must be unique, got {names}")
    if not names:
        raise ValueError("no estimators to run")
    workers = Integer(low=1).check("workers", workers, prefix="")
    trials = list(trials)
    owned = backend is None
    backend = make_backend("local", int(workers)) if owned else backend
    try:
        result = run_tasks(
            partial(run_trial, estimators=estimators, seed=seed), [Task(t.index, t) for t in trials], backend,
            journal=journal, done=dict(done or {}), warmup=partial(warm_up_estimators, estimators) if warmup else None,
            chunk=chunk, progress=progress, desc=desc, unit="frame",
        )
    finally:
        if owned:
            backend.close()
    return [row for t in trials for row in result.results[t.index]]
