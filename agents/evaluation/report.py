"""The report of an evaluation: its summary, the comparison tables, the figures and the output files.

:func:`summarize_evaluation` turns the per-frame rows into a JSON-ready summary (both sweeps per
method, the adaptive runs, the hypotheses needed for the success target), with the statistics of
:func:`stereovo.benchmark.aggregate`; :func:`evaluation_markdown` writes its tables with
:func:`stereovo.benchmark.markdown_table`, :func:`write_plots` its two figures with the helpers of
:mod:`stereovo.reporting`, and :func:`write_evaluation` the files of a run folder.
"""

from __future__ import annotations

import math
import os
from dataclasses import asdict
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from agents.evaluation.setup import (
    KIND_ADAPTIVE,
    KIND_AGENT,
    KIND_AGENT_ADAPTIVE,
    KIND_FIXED,
    KIND_ORACLE,
    KIND_TEXTBOOK,
    EvalConfig,
    EvaluationResult,
)
from stereovo.benchmark import aggregate, markdown_table, success_definition
from stereovo.reporting import (
    ERROR_FLOOR,
    MAX_LINES_PER_PANEL,
    check_plot_format,
    figure,
    format_number,
    format_percent,
    line_style,
    plot_success,
    save_figure,
    wilson_interval,
)

STAT_KEYS: tuple[str, ...] = (
    "frames", "success_rate", "median_rot_err_deg", "median_trans_err_m", "mean_precision", "mean_recall",
    "mean_hypotheses", "median_hypotheses", "n_failed", "n_errors", "median_time_ms",
)
TIME_KEYS: tuple[str, ...] = ("median_time_ms",)


ADAPTIVE_KINDS = (KIND_ADAPTIVE, KIND_TEXTBOOK, KIND_AGENT_ADAPTIVE)
"""Rows that stop on their own (no budget): reported beside the budget sweep, not in it."""

RECIPES: dict[str, str] = {
    KIND_AGENT: "the environment's recipe (sample polish + final refinement) at the budget",
    KIND_ORACLE: "the environment's recipe at the budget, sampling only the true inliers (an upper bound)",
    KIND_FIXED: "the environment's recipe at the budget, the method's own sampler and scoring",
    KIND_ADAPTIVE: "its own adaptive stop with the environment's recipe (sample polish + final refinement)",
    KIND_TEXTBOOK: "its own adaptive stop with the core's defaults (the paper's recipe: no polish, no refinement)",
    KIND_AGENT_ADAPTIVE: "the agent's priors with the prior-aware adaptive stop and the environment's recipe",
}
"""What each kind of row runs; the tables and the figures' captions name it."""


def _stats(rows: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    agg = aggregate(rows)
    return {k: _json_number(agg[k]) for k in STAT_KEYS}


def _json_number(value: Any) -> Any:
    if isinstance(value, (float, np.floating)):
        value = float(value)
        return value if math.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    return value


def summarize_evaluation(
    rows: Sequence[Mapping[str, Any]], config: EvalConfig, agent_order: Sequence[str] = ()
) -> dict[str, Any]:
    """A JSON-ready summary: both sweeps per method, the adaptive runs, hypotheses for 99 % success.

    Keys of the per-value dicts are strings (``"0.8"``, ``"16"``) so the summary survives JSON.
    """
    kinds = {r["method"]: r["kind"] for r in rows}
    rank = {KIND_AGENT: 0, KIND_ORACLE: 1, KIND_FIXED: 2, KIND_ADAPTIVE: 3, KIND_TEXTBOOK: 4, KIND_AGENT_ADAPTIVE: 5}
    first_seen = list(dict.fromkeys(r["method"] for r in rows))
    agent_pos = {name: i for i, name in enumerate(agent_order)}
    methods = sorted(first_seen, key=lambda m: (rank[kinds[m]], agent_pos.get(m, 0), first_seen.index(m)))

    groups: dict[tuple, list[Mapping[str, Any]]] = {}
    for r in rows:
        groups.setdefault((r["method"], float(r["epsilon"]), int(r["budget"])), []).append(r)

    def stats(method: str, epsilon: float, budget: int) -> dict[str, Any] | None:
        group = groups.get((method, epsilon, budget))
        return _stats(group) if group else None

    eps_sweep = {
        m: {f"{e:g}": s for e in config.epsilons if (s := stats(m, e, config.budget)) is not None} for m in methods
    }
    budget_methods = [m for m in methods if kinds[m] not in ADAPTIVE_KINDS]
    budget_sweep = {
        m: {str(b): s for b in config.budgets if (s := stats(m, config.sweep_epsilon, b)) is not None}
        for m in budget_methods
    }
    adaptive = {
        m: s for m in methods if kinds[m] in ADAPTIVE_KINDS
        if (s := stats(m, config.sweep_epsilon, config.budget)) is not None
    }
    needed: dict[str, int | None] = {}
    for m in budget_methods:
        reached = [b for b in config.budgets
                   if budget_sweep[m].get(str(b), {}).get("success_rate", -1.0) >= config.success_target]
        needed[m] = min(reached) if reached else None
    return {
        "config": config.as_dict(),
        # the AUC the frames had: the config's, else env_kwargs', else the env id's own
        "score_aucs": sorted({float(r["score_auc"]) for r in rows}),
        "success_definition": success_definition(),
        "methods": [{"name": m, "kind": kinds[m]} for m in methods],
        "epsilon_sweep": {"budget": config.budget, "epsilons": list(config.epsilons), "methods": eps_sweep},
        "budget_sweep": {"epsilon": config.sweep_epsilon, "budgets": list(config.budgets), "methods": budget_sweep,
                         "adaptive": adaptive},
        "hypotheses_for_success": {"target": config.success_target, "epsilon": config.sweep_epsilon,
                                   "max_budget": max(config.budgets), "methods": needed},
    }


def hypotheses_label(summary: Mapping[str, Any], method: str) -> str:
    h = summary["hypotheses_for_success"]
    value = h["methods"].get(method)
    return f"> {h['max_budget']}" if value is None else str(value)


def evaluation_markdown(summary: Mapping[str, Any], wall_s: float | None = None) -> str:
    """The comparison tables (markdown)."""
    cfg = summary["config"]
    kinds = {m["name"]: m["kind"] for m in summary["methods"]}
    eps = summary["epsilon_sweep"]
    bud = summary["budget_sweep"]
    hyp = summary["hypotheses_for_success"]
    frames = cfg["episodes"] * cfg["frames_per_episode"]
    env_kwargs = dict(cfg.get("env_kwargs") or {})
    env_kwargs.pop("score_auc", None)  # the header states the AUC the rows' frames had, once
    aucs = summary["score_aucs"]
    lines = [
        "# Agents vs classical methods on the same frames",
        "",
        f"Environment `{cfg['env_id']}`"
        + "".join(f", {k}={v!r}" for k, v in sorted(env_kwargs.items()))
        + f", N = {cfg['n']}" + (f", score AUC {', '.join(f'{a:g}' for a in aucs)}" if aucs else "")
        + f", {cfg['episodes']} episodes x {cfg['frames_per_episode']}"
        f" frames = {frames} frames per setting, episode seeds {cfg['seed']}..{cfg['seed'] + cfg['episodes'] - 1}"
        f" (identical frames for every agent and method of a setting). Success = {summary['success_definition']}.",
        f"Agents and `(fixed)` methods draw exactly the budget's hypotheses with the environment's estimator"
        f" recipe (sample polish + final refinement); `(adaptive)` methods stop on their own with the same recipe,"
        f" `(adaptive, textbook)` ones with the core's defaults (the paper's recipe: no polish, no refinement),"
        f" both capped at {cfg['max_iterations']} hypotheses. The oracle reads the ground-truth labels: an upper"
        f" bound only.",
    ]
    if wall_s is not None:
        lines.append(f"Wall time {wall_s:.0f} s.")
    lines.append("")

    def table(title: str, per: Mapping[str, Mapping[str, Any]], keys: Sequence[str], header: str, stat: str,
              fmt: Callable[[Any], str], extra: tuple[str, Callable[[str], str]] | None = None) -> None:
        headers = ["method", "kind", *(f"{header} = {k}" for k in keys)]
        if extra:
            headers.append(extra[0])
        body = []
        for m, values in per.items():
            row = [f"`{m}`", kinds[m], *(fmt(values.get(k, {}).get(stat)) for k in keys)]
            if extra:
                row.append(extra[1](m))
            body.append(row)
        lines.extend([f"## {title}", "", markdown_table(headers, body, "ll" + "r" * (len(headers) - 2)), ""])

    eps_keys = [f"{e:g}" for e in eps["epsilons"]]
    table(f"(a) Success rate vs contamination, budget {eps['budget']}", eps["methods"], eps_keys, "eps",
          "success_rate", format_percent)
    table(f"(a) Median rotation error [deg] vs contamination, budget {eps['budget']}", eps["methods"], eps_keys,
          "eps", "median_rot_err_deg", format_number)
    table(f"(a) Median translation error [m] vs contamination, budget {eps['budget']}", eps["methods"], eps_keys,
          "eps", "median_trans_err_m", format_number)
    bud_keys = [str(b) for b in bud["budgets"]]
    table(f"(b) Success rate vs hypothesis budget, eps {bud['epsilon']:g}", bud["methods"], bud_keys, "budget",
          "success_rate", format_percent,
          (f"hyp. for {100 * hyp['target']:g} %", lambda m: hypotheses_label(summary, m)))
    if bud["adaptive"]:
        body = [[f"`{m}`", format_percent(s["success_rate"]), format_number(s["mean_hypotheses"], ".0f"),
                 format_number(s["median_hypotheses"], ".0f"), format_number(s["median_time_ms"], ".1f")]
                for m, s in bud["adaptive"].items()]
        lines += [f"## (b) Adaptive runs at eps {bud['epsilon']:g} (classical methods: their own stopping rule,"
                  f" with the environment's recipe or the textbook one; `<agent> (adaptive)`: the agent's priors"
                  f" with the prior-aware stop)", "",
                  markdown_table(["method", "success", "hypotheses mean", "hypotheses med", "time med [ms]"], body),
                  ""]
    body = [[f"`{m}`", kinds[m], hypotheses_label(summary, m)] for m in hyp["methods"]]
    lines += [f"## Hypotheses needed for {100 * hyp['target']:g} % success at eps {hyp['epsilon']:g}"
              f" (smallest budget of the sweep)", "", markdown_table(["method", "kind", "hypotheses"], body, "llr"), ""]
    return "\n".join(lines).rstrip() + "\n"


PLOT_NAMES = ("success_vs_epsilon", "success_vs_budget")
PLOT_FILES = tuple(f"{name}.png" for name in PLOT_NAMES)
"""The figures' file names in the default format (PNG); ``write_plots(..., fmt=)`` writes pdf or svg."""


_KIND_LINES = {KIND_AGENT: "-", KIND_ORACLE: ":", KIND_FIXED: "--", KIND_ADAPTIVE: "-", KIND_TEXTBOOK: ":",
               KIND_AGENT_ADAPTIVE: "-."}


def _base_name(method: str) -> str:
    return method.split(" (", 1)[0]


def series_styles(summary: Mapping[str, Any]) -> dict[str, dict[str, Any]]:
    """One style a row, the same in every panel and figure: a colour per agent or classical method
    (its fixed, adaptive and textbook rows share it, told apart by line style and marker fill), a
    line style per kind (:data:`RECIPES`)."""
    kinds = {m["name"]: m["kind"] for m in summary["methods"]}
    colours: dict[str, int] = {}
    for m in kinds:
        colours.setdefault(_base_name(m), len(colours))
    styles = {}
    for m, kind in kinds.items():
        style = line_style(colours[_base_name(m)])
        style["linestyle"] = _KIND_LINES[kind]
        if kind == KIND_TEXTBOOK:
            style["markerfacecolor"] = "white"
        styles[m] = style
    return styles


def _groups(summary: Mapping[str, Any], kinds_of_group: Sequence[tuple[str, tuple[str, ...]]],
            methods: Sequence[str]) -> list[tuple[str, list[str]]]:
    """``(title, methods)`` panels: one per group of kinds that has rows, split to at most
    :data:`MAX_LINES_PER_PANEL` lines each."""
    kinds = {m["name"]: m["kind"] for m in summary["methods"]}
    panels = []
    for title, group in kinds_of_group:
        members = [m for m in methods if kinds[m] in group]
        parts = max(math.ceil(len(members) / MAX_LINES_PER_PANEL), 1)
        size = math.ceil(len(members) / parts) if members else 0
        for p in range(parts):
            chunk = members[p * size:(p + 1) * size]
            if chunk:
                panels.append((title + (f" ({p + 1}/{parts})" if parts > 1 else ""), chunk))
    return panels


def _legend(ax) -> None:
    ax.legend(loc="center left", bbox_to_anchor=(1.01, 0.5), fontsize="small", frameon=False)


def _log_limits(values: Sequence[float]) -> tuple[float, float]:
    """Log-axis limits a little outside the data's range (a factor 1.4 each side)."""
    values = [v for v in values if v is not None and v > 0 and math.isfinite(v)]
    if not values:
        return 1.0, 10.0
    return min(values) / 1.4, max(values) * 1.4


def write_plots(summary: Mapping[str, Any], out: str | os.PathLike, fmt: str = "png") -> list[Path]:
    """(a) success and median pose errors vs contamination; (b) success vs hypothesis budget, and the
    adaptive runs' success against the hypotheses they drew.

    Agents and classical methods are drawn in separate panels (at most
    :data:`~stereovo.reporting.MAX_LINES_PER_PANEL` lines each), every row in the same style in every
    panel (:func:`series_styles`); each panel's title names the recipe its rows run
    (:data:`RECIPES`). Success rates carry their 95 % Wilson band (the adaptive runs' points an error
    bar) over the frames behind each point; ``fmt`` is the file format (png, pdf or svg).
    """
    fmt = check_plot_format(fmt)
    names = [f"{name}.{fmt}" for name in PLOT_NAMES]
    out = Path(out)
    styles = series_styles(summary)
    cfg = summary["config"]
    eps = summary["epsilon_sweep"]
    frames = cfg["episodes"] * cfg["frames_per_episode"]
    rows_a = _groups(summary, (
        ("agents", (KIND_AGENT, KIND_ORACLE)),
        (f"classical, fixed budget of {eps['budget']}", (KIND_FIXED,)),
        (f"classical, own stop (cap {cfg['max_iterations']}): environment's recipe (solid), textbook (dotted)",
         (KIND_ADAPTIVE, KIND_TEXTBOOK)),
        ("agents, own prior-aware stop", (KIND_AGENT_ADAPTIVE,)),
    ), list(eps["methods"]))
    panels = (("success_rate", "success rate [%]", False), ("median_rot_err_deg", "median rotation error [deg]", True),
              ("median_trans_err_m", "median translation error [m]", True))
    fig = figure((16, 3.3 * len(rows_a) + 0.8))
    grid = fig.subplots(len(rows_a), 3, squeeze=False, sharex=True, sharey="col")
    for r, (title, members) in enumerate(rows_a):
        for c, (key, ylabel, logy) in enumerate(panels):
            ax = grid[r][c]
            for m in members:
                pts = [(float(e), s[key], s.get("frames") or 0) for e, s in eps["methods"][m].items()
                       if s.get(key) is not None]
                if not pts:
                    continue
                xs, ys, ns = zip(*sorted(pts))
                if key == "success_rate":
                    plot_success(ax, xs, ys, ns, m, styles[m])
                else:
                    ax.plot(xs, [max(y, ERROR_FLOOR) for y in ys], label=m, lw=1.3, ms=4, **styles[m])
            if logy:
                ax.set_yscale("log")
            else:
                ax.set_ylim(-2, 102)
            ax.set_xticks(list(eps["epsilons"]))
            ax.set_ylabel(ylabel, fontsize="small")
            ax.grid(True, which="both", alpha=0.3)
            if r == len(rows_a) - 1:
                ax.set_xlabel("contamination epsilon")
        grid[r][0].set_title(title, fontsize="small", loc="left")
        _legend(grid[r][2])
    fig.suptitle(f"(a) vs contamination at a budget of {eps['budget']} hypotheses; {frames} frames a point,"
                 f" bands: 95 % Wilson intervals (a wiggle inside a band is noise). Agents and fixed rows run the"
                 f" environment's recipe (sample polish + final refinement)", fontsize="small")
    paths = [save_figure(fig, out / names[0])]

    bud = summary["budget_sweep"]
    rows_b = _groups(summary, (("agents", (KIND_AGENT, KIND_ORACLE)), ("classical, fixed budget", (KIND_FIXED,))),
                     list(bud["methods"]))
    adaptive = [m for m in bud["adaptive"] if bud["adaptive"][m].get("mean_hypotheses")]
    n_panels = len(rows_b) + bool(adaptive)
    fig = figure((5.6 * n_panels, 6.4))
    axes = fig.subplots(1, n_panels, squeeze=False, sharey=True)[0]
    target = summary["hypotheses_for_success"]["target"]
    budgets = list(bud["budgets"])
    for ax, (title, members) in zip(axes, rows_b):
        for m in members:
            pts = [(int(b), s["success_rate"], s.get("frames") or 0) for b, s in bud["methods"][m].items()
                   if s.get("success_rate") is not None]
            if pts:
                xs, ys, ns = zip(*sorted(pts))
                plot_success(ax, xs, ys, ns, m, styles[m])
        ax.set_xscale("log", base=2)
        ax.set_xlim(*_log_limits(budgets))
        ax.set_xticks(budgets)
        ax.set_xticklabels([str(b) for b in budgets])
        ax.minorticks_off()
        ax.set_xlabel("hypotheses per frame (budget)")
        ax.set_title(f"{title}: environment's recipe", fontsize="small", loc="left")
    if adaptive:
        ax = axes[-1]
        for m in adaptive:
            s = bud["adaptive"][m]
            n = s.get("frames") or 0
            low, high = wilson_interval(np.array([s["success_rate"] * n]), np.array([n]))
            y = 100 * s["success_rate"]
            ax.errorbar([s["mean_hypotheses"]], [y], yerr=[[y - 100 * low[0]], [100 * high[0] - y]],
                        color=styles[m]["color"], marker=styles[m]["marker"], ms=7, capsize=3, lw=1.2,
                        markerfacecolor=styles[m].get("markerfacecolor", styles[m]["color"]),
                        linestyle="none", label=m)
        ax.set_xscale("log")
        ax.set_xlim(*_log_limits([bud["adaptive"][m]["mean_hypotheses"] for m in adaptive]))
        ax.set_xlabel("mean hypotheses drawn per frame")
        ax.set_title("own stop: environment's recipe (filled), textbook (hollow)", fontsize="small", loc="left")
    for ax in axes:
        ax.axhline(100 * target, color="tab:red", ls="--", lw=0.8, label=f"{100 * target:g} % success")
        ax.set_ylim(-2, 102)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=2, fontsize="small", frameon=False)
    axes[0].set_ylabel("success rate [%]")
    fig.suptitle(f"(b) Success vs hypotheses at eps {bud['epsilon']:g}; {frames} frames a point, 95 % Wilson"
                 f" bands / bars", fontsize="small")
    paths.append(save_figure(fig, out / names[1]))
    return paths


def plot_success_vs_budget(path: str | os.PathLike, rows: Sequence[Mapping[str, Any]], label_key: str,
                           title: str) -> None:
    """Success (%) against the fixed budgets, one line per ``rows[i][label_key]``, the Wilson 95 %
    intervals as error bars; rows carry ``budget``, ``success``, ``ci_low``, ``ci_high`` (a budget
    ``"adaptive"`` has no place on the axis and is left out)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7, 4.2))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    for label in dict.fromkeys(r[label_key] for r in rows):
        own = [r for r in rows if r[label_key] == label and r["budget"] != "adaptive"]
        budgets = np.array([r["budget"] for r in own], float)
        success = 100 * np.array([r["success"] for r in own])
        err = 100 * np.array([[r["success"] - r["ci_low"], r["ci_high"] - r["success"]] for r in own]).T
        ax.errorbar(budgets, success, yerr=err, marker="o", capsize=3, label=label)
    ax.set_xscale("log", base=2)
    ax.set_xlabel("hypotheses per frame (fixed budget)")
    ax.set_ylabel("frames within 1 deg / 5 cm (%)")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def write_evaluation(result: EvaluationResult, out: str | os.PathLike, plots: bool = True,
                     plot_format: str = "png") -> list[Path]:
    """``frames.csv`` (per-frame rows), ``summary.json``, ``summary.md`` and the plots (``plot_format``:
    png, pdf or svg) under ``out``."""
    if plots:
        check_plot_format(plot_format)  # before anything is written
    import json

    from stereovo.io import write_frame_csv

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    from stereovo.trials.store import atomic_path, atomic_write_text

    with atomic_path(out / "frames.csv") as tmp:  # a reader never sees half a file
        write_frame_csv(tmp, result.rows)
    payload = {**result.summary, "agents": [asdict(a) for a in result.agents], "wall_s": round(result.wall_s, 1)}
    atomic_write_text(out / "summary.json", json.dumps(payload, indent=2) + "\n")
    atomic_write_text(out / "summary.md", evaluation_markdown(result.summary, result.wall_s))
    paths = [out / "frames.csv", out / "summary.json", out / "summary.md"]
    if plots:
        paths += write_plots(result.summary, out, plot_format)
    return paths
