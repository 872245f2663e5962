"""The classical baselines' report, ``docs/baselines.md``: rebuilt from a ``vo-gym baselines`` run folder.

:func:`write_baseline_report` recomputes the summary and the claim checks from the run's
``trials.csv`` (its only source of truth), copies or redraws its figures into ``docs/img/NAME/``
and writes the markdown: setup, methods, results (:mod:`~stereovo.benchmark.tables`), the
textbook rows beside their '+ enhancement' rows, the claims and the figures. The command is
``scripts/make_baseline_report.py``.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

from stereovo.benchmark.aggregation import BenchmarkSummary, read_trials_csv, summarize
from stereovo.benchmark.claims import check_claims
from stereovo.benchmark.diagnostics import claim_diagnostics
from stereovo.benchmark.grid import DEFAULT_GRID, FULL_GRID
from stereovo.benchmark.plots import PLOT_FILES, write_plots
from stereovo.benchmark.runner import GUIDED_VARIANTS, describe_method
from stereovo.benchmark.tables import claims_markdown, format_stat, markdown_table, success_definition, summary_markdown

__all__ = ["REPORT_NAME", "enhancement_pairs", "enhancement_section", "write_baseline_report"]

REPORT_NAME = "baselines"

# ``vo-gym baselines``' flag of each axis of BenchmarkGrid.as_dict(), for the report's command line
_AXIS_FLAGS = {"epsilons": "--epsilons", "noise_sigmas": "--sigmas", "score_aucs": "--aucs", "ns": "--ns",
               "outlier_kinds": "--outlier-kinds", "frames_per_cell": "--frames-per-cell",
               "preset": "--preset", "max_iterations": "--max-iterations"}


def grid_flags(settings: dict) -> str:
    """The ``vo-gym baselines`` flags that rebuild a run's grid from ``run.json``'s ``settings``:
    ``--full`` for the full grid, then each axis that differs from the default (or full) grid's,
    e.g. ``" --outlier-kinds hostile"``; ``""`` for the default grid or a run without its axes."""
    full = bool(settings.get("full"))
    flags = " --full --backend ray" if full else ""
    axes = settings.get("grid_axes")
    if not isinstance(axes, dict):
        return flags
    base = (FULL_GRID if full else DEFAULT_GRID).as_dict()
    for axis, flag in _AXIS_FLAGS.items():
        value = axes.get(axis)
        if value is None or value == base[axis]:
            continue
        text = ",".join(f"{v:g}" if isinstance(v, float) else str(v) for v in value) \
            if isinstance(value, list) else str(value)
        flags += f" {flag} {text}"
    return flags
"""The default report's name: ``docs/baselines.md`` and ``docs/img/baselines/``."""


def enhancement_pairs(summary: BenchmarkSummary) -> list[tuple[str, list[str]]]:
    """``(textbook method, its '+ enhancement' rows)`` for every textbook row of the run that has any.

    An enhancement row is named ``<method>+<addition>[+...]`` (the registry's enhancement variants);
    the guided variants (match scores as inputs) are left out: they change the input, not the recipe.
    """
    pairs = []
    for base in summary.methods:
        if "+" in base:
            continue
        variants = [m for m in summary.methods
                    if m.startswith(base + "+") and m not in GUIDED_VARIANTS]
        if variants:
            pairs.append((base, variants))
    return pairs


def enhancement_section(summary: BenchmarkSummary) -> list[str]:
    """A table of each textbook row beside its '+ enhancement' rows: what each addition buys."""
    pairs = enhancement_pairs(summary)
    if not pairs:
        return []
    heavy = summary.epsilons[-1] if summary.epsilons else None
    headers = ["method", "success", f"success at epsilon {heavy:g}" if heavy is not None else "success (heaviest)",
               "rot err med [deg]", "trans err med [m]", "hypotheses mean", "time med [ms]", "success vs textbook"]
    rows = []
    for base, variants in pairs:
        ref = summary.overall[base].get("success_rate")
        for m in [base, *variants]:
            o = summary.overall[m]
            h = summary.by_epsilon.get(m, {}).get(heavy, {}) if heavy is not None else {}
            delta = "textbook" if m == base else f"{100 * (o.get('success_rate') - ref):+.1f} points"
            rows.append([f"`{m}`" if m == base else f"&nbsp;&nbsp;`{m}`",
                         format_stat("success_rate", o.get("success_rate")),
                         format_stat("success_rate", h.get("success_rate")),
                         format_stat("median_rot_err_deg", o.get("median_rot_err_deg")),
                         format_stat("median_trans_err_m", o.get("median_trans_err_m")),
                         format_stat("mean_hypotheses", o.get("mean_hypotheses")),
                         format_stat("median_time_ms", o.get("median_time_ms")), delta])
    return [
        "### Textbook rows and '+ enhancement' rows",
        "",
        "Each named method runs its paper's recipe (minimal closed-form fits, the paper's score and stop, one"
        " least-squares refit of the final inliers); the project's additions are separate rows named"
        " `<method>+<addition>`: `+polish` (2 Gauss-Newton steps of each minimal fit on its points' reprojection"
        " error), `+refit` (each new best refitted on its consensus), `+rigidity` (samples whose pairwise"
        " distances change beyond their noise are dropped unfitted), `+lm` (iterated two-image LM refinement of"
        " the final model). Same frames, same seeds; the last column is the success rate minus the textbook row's.",
        "",
        markdown_table(headers, rows),
        "",
    ]


def write_baseline_report(run_dir: Path, docs_dir: Path, redraw: bool = False, name: str = REPORT_NAME) -> Path:
    """Write ``docs_dir/<name>.md`` and its figures (``docs_dir/img/<name>/``) from the run in ``run_dir``.

    Returns the markdown path.

    The run's PNGs are copied; with ``redraw`` (or when the run has none) they are drawn again from ``trials.csv``.
    """
    run_dir, docs_dir = Path(run_dir), Path(docs_dir)
    trials = run_dir / "trials.csv"
    if not trials.is_file():
        raise FileNotFoundError(f"{trials} not found: run `vo-gym baselines --out {run_dir}` first")
    settings_path = run_dir / "run.json"
    settings = json.loads(settings_path.read_text()) if settings_path.is_file() else {}
    rows = read_trials_csv(trials)
    summary = summarize(rows)
    # measured figures that explain the verdicts, on the run's own frames (re-simulated with its seed)
    claims = check_claims(summary, claim_diagnostics(rows, int(settings.get("seed", 0))))

    image_rel = Path("img") / name
    image_dir = docs_dir / image_rel
    image_dir.mkdir(parents=True, exist_ok=True)
    if not redraw and all((run_dir / figure).is_file() for figure in PLOT_FILES):
        for figure in PLOT_FILES:
            shutil.copyfile(run_dir / figure, image_dir / figure)
    else:
        write_plots(rows, summary, image_dir)

    methods = settings.get("methods") or summary.methods
    descriptions = settings.get("method_descriptions") or {}
    kinds = (settings.get("grid_axes") or {}).get("outlier_kinds")
    other_kinds = isinstance(kinds, list) and kinds != list(DEFAULT_GRID.outlier_kinds) and not settings.get("full")
    lines = [
        "# Classical baselines" + (f" (outlier kinds: {', '.join(map(str, kinds))})" if other_kinds else ""),
        "",
        "<!-- Generated by scripts/make_baseline_report.py from a `vo-gym baselines` run; do not edit by hand. -->",
        "",
        "Every classical method of the estimator core on one benchmark grid of simulated stereo frame pairs;"
        " every method sees the identical frames (one seeded frame per grid cell and repeat). The learned"
        " samplers of `vo-gym evaluate` have to beat these numbers on the same frames.",
        "",
        "Reproduce:",
        "",
        "```bash",
        f"vo-gym baselines --seed {settings.get('seed', 0)} --out runs/{name}" + grid_flags(settings),
        f"python scripts/make_baseline_report.py --from runs/{name}"
        + (f" --name {name}" if name != REPORT_NAME else ""),
        "```",
        "",
        "## Setup",
        "",
        f"- Grid: {settings.get('grid', 'see trials.csv')}.",
        f"- Seed {settings.get('seed', 'n/a')}; {settings.get('workers', 'n/a')} worker process(es);"
        f" {settings.get('n_trials', len({r['trial'] for r in rows}))} frames x {len(methods)} methods"
        + (f" in {settings['wall_s']:.0f} s" if settings.get("wall_s") is not None else "")
        + (f" on {settings['machine']}" if settings.get("machine") else "")
        + (f" (the last invocation, a `--resume` that ran {settings['n_trials'] - settings['n_resumed']} of"
           f" them; the other {settings['n_resumed']} came from the run's journal)"
           if settings.get("n_resumed") and settings.get("n_trials") else "") + ".",
        f"- Success: {success_definition()}.",
        "- Time: wall time of one estimator call, measured while the other workers run (relative"
        " comparisons are fair: every method runs on the same frames in the same process, one after another).",
        "- Hypotheses are drawn in vectorised batches: a first batch of 16, then batches doubling up to 128"
        " (16, 32, 64, 128, ...), so 16 is the floor of every adaptive sampling method.",
        "- Frames depend on (seed, epsilon, N, outlier kind, repeat) only: cells that differ in noise or"
        " AUC share their geometry (common random numbers).",
        "",
        "Methods:",
        "",
    ]
    lines += [f"- `{m}`: {descriptions.get(m) or describe_method(m)}" for m in methods]
    lines += ["", summary_markdown(summary, {"max_iterations": settings.get("max_iterations")}, title="Results", level=2).rstrip(), ""]
    lines += enhancement_section(summary)
    lines += [claims_markdown(claims, heading="## Claims of the seed vs our numbers").rstrip(), ""]
    lines += ["## Figures", ""]
    captions = {
        "success_vs_epsilon.png": "Success rate vs contamination",
        "hypotheses_vs_epsilon.png": "Hypotheses generated vs contamination",
        "time_vs_n.png": "Median time vs N",
        "error_cdf.png": "Rotation and translation error CDFs",
    }
    for figure in PLOT_FILES:
        lines += [f"![{captions[figure]}]({(image_rel / figure).as_posix()})", ""]
    out = docs_dir / f"{name}.md"
    out.write_text("\n".join(lines).rstrip() + "\n")
    return out
