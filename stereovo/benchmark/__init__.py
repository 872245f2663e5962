"""Estimator comparisons on simulated frames, shared by the classical baselines and the agents' evaluation.

The ``vo-gym baselines`` command runs the classical RANSAC family here, and
``vo-gym evaluate`` (:mod:`agents.evaluation`) reuses the same pieces to put
learned agents side by side with them on the *same* frames.

Vocabulary:

- A :class:`GridCell` is one simulator setting: contamination epsilon, pixel
  noise sigma, match-score AUC, number of correspondences N and outlier kind.
- A :class:`BenchmarkGrid` is the product of its axes times ``frames_per_cell``
  repeats; :meth:`BenchmarkGrid.trials` lists the :class:`Trial` s.
- A trial is one simulated frame pair. Every estimator of a run sees the
  identical frame, and one row per (trial, estimator) is recorded.
- An *estimator* is any picklable callable ``(frame, rng) -> estimate`` where
  the estimate has the fields of :class:`stereovo.estimation.MotionEstimate`
  that :func:`stereovo.metrics.frame_metrics` reads. :class:`ClassicalEstimator`
  wraps a registered method; a learned agent is just another callable.

The modules, in the order a run goes through them (each imports only those
before it):

- :mod:`~stereovo.benchmark.grid`: the grid, its trials and their seeds
  (same seed, same rows);
- :mod:`~stereovo.benchmark.runner`: the estimators and the runner, rows with
  :data:`TRIAL_COLUMNS`;
- :mod:`~stereovo.benchmark.aggregation`: rows read back from CSV and their
  statistics (:class:`BenchmarkSummary`);
- :mod:`~stereovo.benchmark.claims` and :mod:`~stereovo.benchmark.diagnostics`:
  the seed's claims judged against the statistics, and the measured figures
  that explain the verdicts;
- :mod:`~stereovo.benchmark.tables` and :mod:`~stereovo.benchmark.plots`: the
  report's markdown and figures;
- :mod:`~stereovo.benchmark.outputs`: the files of a run folder;
- :mod:`~stereovo.benchmark.baseline_report`: ``docs/baselines.md`` rebuilt from a run
  folder (the claims recomputed, the figures copied or redrawn).

Beside the grid: :mod:`~stereovo.benchmark.on_images` runs the estimators on an image sequence's
own frames (``vo-gym baselines --source rendered``), and :mod:`~stereovo.benchmark.peers` and
:mod:`~stereovo.benchmark.speed_accuracy` time the core against other libraries. These three are
imported by their module path.

Every public name of the modules is importable from the package itself.
"""

from __future__ import annotations

from stereovo.benchmark.aggregation import (
    STAT_LABELS,
    BenchmarkSummary,
    aggregate,
    cell_summary_rows,
    finite_stat,
    group_rows,
    parse_trial_value,
    read_trials_csv,
    summarize,
    typed_value,
)
from stereovo.benchmark.claims import (
    ACCURACY_RATIO,
    AGREES,
    CONSTANT_TIME_SPREAD,
    COST_RATIO,
    CUT_RATIO,
    DISAGREES,
    HEAVY_EPSILON,
    NOT_MEASURED,
    QUADRATIC_SLOPE,
    ROBUST_MARGIN,
    SUCCESS_MARGIN,
    UNRELIABLE_DROP,
    UNRELIABLE_MAX,
    ClaimCheck,
    check_claims,
    preemptive_miss_probability,
    thresholds_text,
)
from stereovo.benchmark.diagnostics import DIAGNOSTIC_FRAMES, claim_diagnostics
from stereovo.benchmark.grid import (
    DEFAULT_GRID,
    DEFAULT_MAX_ITERATIONS,
    FULL_GRID,
    OUTLIER_MIXES,
    BenchmarkGrid,
    GridCell,
    Trial,
    check_seed,
    estimator_seed,
    frame_seed,
    quantize,
    simulate_trial,
    stable_int,
)
from stereovo.benchmark.outputs import write_outputs
from stereovo.benchmark.baseline_report import (
    REPORT_NAME,
    enhancement_pairs,
    enhancement_section,
    write_baseline_report,
)
from stereovo.benchmark.plots import (
    FAMILY_TITLES,
    METHOD_FAMILIES,
    PLOT_FILES,
    PLOT_NAMES,
    REFERENCE_METHOD,
    method_family,
    plot_error_cdf,
    plot_files,
    plot_panels,
    write_plots,
)
from stereovo.benchmark.runner import (
    GUIDED_VARIANTS,
    METHOD_INPUTS,
    TIME_COLUMNS,
    TRIAL_COLUMNS,
    ClassicalEstimator,
    Estimator,
    benchmark_methods,
    classical_estimators,
    default_workers,
    describe_method,
    measure_estimator,
    ordered_map,
    run_benchmark,
    run_trial,
    score_inputs,
    warm_up_estimators,
)
from stereovo.benchmark.tables import (
    breakdown_table,
    claims_markdown,
    format_stat,
    markdown_table,
    overall_table,
    success_definition,
    summary_markdown,
)

__all__ = [
    "OUTLIER_MIXES",
    "METHOD_INPUTS",
    "GUIDED_VARIANTS",
    "TIME_COLUMNS",
    "DEFAULT_GRID",
    "FULL_GRID",
    "GridCell",
    "BenchmarkGrid",
    "Trial",
    "Estimator",
    "ClassicalEstimator",
    "benchmark_methods",
    "classical_estimators",
    "frame_seed",
    "estimator_seed",
    "simulate_trial",
    "run_trial",
    "run_benchmark",
    "warm_up_estimators",
    "ordered_map",
    "read_trials_csv",
    "parse_trial_value",
    "BenchmarkSummary",
    "aggregate",
    "summarize",
    "ClaimCheck",
    "check_claims",
    "summary_markdown",
    "claims_markdown",
    "write_plots",
    "write_outputs",
    "write_baseline_report",
]
