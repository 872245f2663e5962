"""The files of a benchmark run folder: the trial rows, their summaries, the markdown report and the figures.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Mapping, Sequence

from stereovo.benchmark.aggregation import BenchmarkSummary, cell_summary_rows, summarize
from stereovo.benchmark.claims import ClaimCheck, check_claims
from stereovo.benchmark.plots import write_plots
from stereovo.benchmark.tables import claims_markdown, summary_markdown
from stereovo.reporting import check_plot_format

def write_outputs(
    rows: Sequence[Mapping[str, Any]], out: str | os.PathLike, settings: Mapping[str, Any] | None = None,
    plots: bool = True, plot_format: str = "png",
) -> tuple[BenchmarkSummary, list[ClaimCheck]]:
    """Write ``trials.csv``, ``cells.csv``, ``summary.csv``, ``summary.md``, ``claims.md`` and the plots
    (``plot_format``: png, pdf or svg)."""
    if plots:
        check_plot_format(plot_format)  # before anything is written
    from stereovo.io import write_frame_csv
    from stereovo.trials.store import atomic_path, atomic_write_text

    out = Path(out)

    def csv_file(name: str, table: Sequence[Mapping[str, Any]]) -> None:
        # Through a temporary file and a rename: a reader never sees half a table.
        with atomic_path(out / name) as tmp:
            write_frame_csv(tmp, table)

    # Everything computed first: a row the statistics cannot take fails before any file is written.
    summary = summarize(rows)
    summary_rows = [{"method": m, **summary.overall[m]} for m in summary.methods]
    cell_rows = cell_summary_rows(rows)
    claims = check_claims(summary)
    summary_md = summary_markdown(summary, settings)
    claims_md = claims_markdown(claims)
    out.mkdir(parents=True, exist_ok=True)
    csv_file("trials.csv", rows)
    csv_file("summary.csv", summary_rows)
    csv_file("cells.csv", cell_rows)
    atomic_write_text(out / "summary.md", summary_md)
    atomic_write_text(out / "claims.md", claims_md)
    if plots:
        write_plots(rows, summary, out, plot_format)
    return summary, claims
