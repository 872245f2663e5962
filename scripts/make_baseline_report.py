#!/usr/bin/env python
"""Regenerate ``docs/baselines.md`` from a ``vo-gym baselines`` run.

Usage::

    vo-gym baselines --out runs/baselines
    python scripts/make_baseline_report.py --from runs/baselines

``--name baselines-full`` writes ``docs/baselines-full.md`` and ``docs/img/baselines-full/``
instead (the report of the full grid, beside the default grid's). Without ``--from`` the default grid is run first (into ``runs/baselines``,
about two minutes on two cores). The summary and the claim checks are
recomputed from ``trials.csv`` (the run's only source of truth), the run's
figures are copied to ``docs/img/baselines/`` (redrawn from the CSV when the
run has none, or with ``--redraw``), and ``docs/baselines.md`` is rewritten.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
REPORT_NAME = "baselines"  # the markdown file and the image folder are named after it


def _fmt(key: str, value) -> str:
    """A table cell in the units of the results table (``n/a`` for a missing value)."""
    import math

    if value is None or not math.isfinite(float(value)):
        return "n/a"
    if key == "success_rate":
        return f"{100 * value:.1f} %"
    if key == "mean_hypotheses":
        return f"{value:,.0f}"
    if key == "median_time_ms":
        return f"{value:.1f}"
    return f"{value:.3g}"


def enhancement_pairs(summary) -> list[tuple[str, list[str]]]:
    """``(textbook method, its '+ enhancement' rows)`` for every textbook row of the run that has any.

    An enhancement row is named ``<method>+<addition>[+...]`` (the registry's enhancement variants);
    the guided variants (match scores as inputs) are left out: they change the input, not the recipe.
    """
    from stereovo import benchmark as bm

    pairs = []
    for base in summary.methods:
        if "+" in base:
            continue
        variants = [m for m in summary.methods
                    if m.startswith(base + "+") and m not in bm.GUIDED_VARIANTS]
        if variants:
            pairs.append((base, variants))
    return pairs


def enhancement_section(summary) -> list[str]:
    """A table of each textbook row beside its '+ enhancement' rows: what each addition buys."""
    from stereovo import benchmark as bm

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
                         _fmt("success_rate", o.get("success_rate")),
                         _fmt("success_rate", h.get("success_rate")),
                         _fmt("median_rot_err_deg", o.get("median_rot_err_deg")),
                         _fmt("median_trans_err_m", o.get("median_trans_err_m")),
                         _fmt("mean_hypotheses", o.get("mean_hypotheses")),
                         _fmt("median_time_ms", o.get("median_time_ms")), delta])
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
        bm.markdown_table(headers, rows),
        "",
    ]


def build_report(run_dir: Path, docs_dir: Path, redraw: bool = False, name: str = REPORT_NAME) -> Path:
    """Write ``docs_dir/<name>.md`` and its figures (``docs_dir/img/<name>/``) from the run in ``run_dir``.

    Returns the markdown path.

    The run's PNGs are copied; with ``redraw`` (or when the run has none) they are drawn again from ``trials.csv``.
    """
    from stereovo import benchmark as bm

    trials = run_dir / "trials.csv"
    if not trials.is_file():
        raise FileNotFoundError(f"{trials} not found: run `vo-gym baselines --out {run_dir}` first")
    settings_path = run_dir / "run.json"
    settings = json.loads(settings_path.read_text()) if settings_path.is_file() else {}
    rows = bm.read_trials_csv(trials)
    summary = bm.summarize(rows)
    # measured figures that explain the verdicts, on the run's own frames (re-simulated with its seed)
    claims = bm.check_claims(summary, bm.claim_diagnostics(rows, int(settings.get("seed", 0))))

    image_rel = Path("img") / name
    image_dir = docs_dir / image_rel
    image_dir.mkdir(parents=True, exist_ok=True)
    if not redraw and all((run_dir / figure).is_file() for figure in bm.PLOT_FILES):
        for figure in bm.PLOT_FILES:
            shutil.copyfile(run_dir / figure, image_dir / figure)
    else:
        bm.write_plots(rows, summary, image_dir)

    methods = settings.get("methods") or summary.methods
    descriptions = settings.get("method_descriptions") or {}
    lines = [
        "# Classical baselines",
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
        f"vo-gym baselines --seed {settings.get('seed', 0)} --out runs/{name}"
        + (" --full --backend ray" if settings.get("full") else ""),
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
        f"- Success: {bm.success_definition()}.",
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
    lines += [f"- `{m}`: {descriptions.get(m) or bm.describe_method(m)}" for m in methods]
    lines += ["", bm.summary_markdown(summary, {"max_iterations": settings.get("max_iterations")}, title="Results", level=2).rstrip(), ""]
    lines += enhancement_section(summary)
    lines += [bm.claims_markdown(claims, heading="## Claims of the seed vs our numbers").rstrip(), ""]
    lines += ["## Figures", ""]
    captions = {
        "success_vs_epsilon.png": "Success rate vs contamination",
        "hypotheses_vs_epsilon.png": "Hypotheses generated vs contamination",
        "time_vs_n.png": "Median time vs N",
        "error_cdf.png": "Rotation and translation error CDFs",
    }
    for figure in bm.PLOT_FILES:
        lines += [f"![{captions[figure]}]({(image_rel / figure).as_posix()})", ""]
    out = docs_dir / f"{name}.md"
    out.write_text("\n".join(lines).rstrip() + "\n")
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--from", dest="run_dir", type=Path, default=None,
                        help="a `vo-gym baselines` output folder (default: run the default grid first)")
    parser.add_argument("--docs", type=Path, default=REPO / "docs", help="docs folder (default: the repo's docs/)")
    parser.add_argument("--out", type=Path, default=Path("runs/baselines"),
                        help="where to run the default grid when --from is not given (default: runs/baselines)")
    parser.add_argument("--name", default=REPORT_NAME,
                        help="report name: docs/NAME.md and docs/img/NAME/ (default: baselines)")
    parser.add_argument("--redraw", action="store_true", help="draw the figures again from trials.csv instead of copying them")
    parser.add_argument("--workers", type=int, default=None, help="worker processes for that run")
    parser.add_argument("--seed", type=int, default=0, help="seed for that run (default: 0)")
    args = parser.parse_args(argv)

    run_dir = args.run_dir
    if run_dir is None:
        from vo_gym_cli.main import main as vo_gym

        cli = ["baselines", "--out", str(args.out), "--seed", str(args.seed)]
        if args.workers:
            cli += ["--workers", str(args.workers)]
        code = vo_gym(cli)
        if code:
            return code
        run_dir = args.out
    try:
        path = build_report(run_dir, args.docs, redraw=args.redraw, name=args.name)
    except FileNotFoundError as err:
        print(f"make_baseline_report: error: {err}", file=sys.stderr)
        return 2
    print(f"wrote {path} and {args.docs / 'img' / args.name}/")
    return 0


if __name__ == "__main__":
    sys.exit(main())
