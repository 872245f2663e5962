"""Speed against accuracy, in the field's own format: success rate and median rotation error
against median time per frame, one curve per estimator as its confidence is swept, and the table
of hypotheses and time against the quality of the match scores.

Every estimator of a curve runs on the same seeded frames (:func:`cell_frames`); each point of a
curve is one setting of the estimator's stopping confidence (ours: ``confidence``; OpenCV and
SupeRANSAC: ``confidence``; PoseLib: ``success_prob``), with the iteration cap at
:data:`~stereovo.benchmark.peers.PEER_MAX_ITERATIONS` for all and PoseLib's and SupeRANSAC's
floor of 1000 iterations lowered to 1, so that the confidence alone sets where each one stops. The runners are
:mod:`stereovo.benchmark.peers`; ``scripts/speed_accuracy.py`` is the command that regenerates
the figure and the table (docs/performance.md).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Callable, Iterable, Sequence

import numpy as np

from stereovo.benchmark import peers

CONFIDENCES = (0.5, 0.8, 0.95, 0.99, 0.999, 0.99999)
EPSILONS = (0.5, 0.8, 0.9)
SCORE_AUCS = (0.5, 0.75, 0.9)
PRESETS = ("default", "random", "hostile")
# "random": every outlier a random mismatch (the bench's default: it corrupts the left pixel at k,
# which every estimator reads). "default" and "hostile" are the simulator's outlier presets.
RANDOM_MIX = (1.0, 0.0, 0.0)


@dataclass
class CurvePoint:
    """One estimator at one setting on one cell's frames."""

    estimator: str
    setting: float
    epsilon: float
    frames: int
    median_ms: float
    success: float
    median_rot_deg: float
    median_hypotheses: float


def simulation_config(n: int, epsilon: float, preset: str, noise: float = 0.5, score_auc: float | None = None):
    """The :class:`~stereovo.simulation.SimulationConfig` of one cell under an outlier ``preset``
    (:data:`PRESETS`); "hostile" is passed on as ``outliers="hostile"``."""
    from stereovo.simulation import SimulationConfig

    if preset not in PRESETS:
        raise ValueError(f"preset must be one of {PRESETS}, got {preset!r}")
    kwargs = dict(n_correspondences=n, outlier_ratio=epsilon, noise_sigma=noise)
    if score_auc is not None:
        kwargs["score_auc"] = score_auc
    if preset == "random":
        kwargs["outlier_mix"] = RANDOM_MIX
    elif preset != "default":
        kwargs["outliers"] = preset
    try:
        return SimulationConfig(**kwargs)
    except TypeError as exc:  # a simulator without that preset
        raise ValueError(f"preset {preset!r}: this simulator does not accept it ({exc})") from None


def cell_frames(config, frames: int, seed: int) -> list:
    """``frames`` frames of ``config``, the same for every estimator of a cell."""
    from stereovo.simulation import simulate_frame

    cell = int(round(config.outlier_ratio * 1000)) + 7919 * config.n_correspondences
    return [simulate_frame(config, np.random.default_rng(s)) for s in np.random.SeedSequence([seed, cell]).spawn(frames)]


def curve_runners(confidence: float, superansac: bool = True) -> dict[str, peers.Runner]:
    """Every estimator of the figure at one ``confidence``, missing peers left out."""
    runners: dict[str, peers.Runner | None] = {
        "ours": peers.ours("probabilistic", "uniform", confidence=confidence),
        "ours + SPRT": peers.ours("probabilistic+sprt", "uniform", confidence=confidence),
        "ours, PROSAC by score": peers.ours("probabilistic", "prosac", confidence=confidence),
        "ours, guided by score": peers.ours("probabilistic", "guided", confidence=confidence),
        "OpenCV": peers.opencv(confidence=confidence),
        "OpenCV USAC": peers.opencv(usac=True, confidence=confidence),
        "PoseLib": peers.poselib(confidence=confidence, min_iterations=1),
    }
    if superansac:
        runners["SupeRANSAC"] = peers.superansac("uniform", confidence=confidence)
        runners["SupeRANSAC, importance by score"] = peers.superansac("importance", confidence=confidence)
    return {name: run for name, run in runners.items() if run is not None}


def measure_cell(runners: dict[tuple[str, float], peers.Runner], frames: Sequence, seed: int, epsilon: float,
                 repeats: int = 1) -> list[CurvePoint]:
    """Run every ``(estimator, setting)`` runner on every frame (seed ``seed + i`` for frame i) and
    summarise each. A frame's runners run one after another, so that a burst of load on a shared
    machine hits all of them; each runs ``repeats`` times and keeps its fastest time (load only
    ever adds time) and its first estimate."""
    records: dict[tuple[str, float], list[tuple[float, float, bool, int]]] = {key: [] for key in runners}
    for i, frame in enumerate(frames):
        for key, run in runners.items():
            out = run(frame, seed + i)
            seconds = min([out.seconds] + [run(frame, seed + i).seconds for _ in range(repeats - 1)])
            rot_deg, _, success = peers.frame_errors(out, frame)
            records[key].append((seconds, rot_deg, success, out.hypotheses))
    points = []
    for (name, setting), rows in records.items():
        times, rot, ok, hyps = zip(*rows)
        known = [h for h in hyps if h >= 0]
        points.append(CurvePoint(name, setting, epsilon, len(rows), 1e3 * float(np.median(times)), float(np.mean(ok)),
                                 float(np.median(rot)), float(np.median(known)) if known else float("nan")))
    return points


def sweep(n: int, epsilons: Iterable[float], preset: str, frames: int, seed: int = 0,
          confidences: Sequence[float] = CONFIDENCES, repeats: int = 1,
          progress: Callable | None = None) -> list[CurvePoint]:
    """Every estimator at every confidence on every epsilon's frames; ``progress(k)`` after each
    epsilon's cell (for a progress bar)."""
    points = []
    for eps in epsilons:
        cell = cell_frames(simulation_config(n, eps, preset), frames, seed)
        runners = {(name, c): run for c in confidences for name, run in curve_runners(c).items()}
        points += measure_cell(runners, cell, seed, eps, repeats)
        if progress is not None:
            progress(1)
    return points


def warm_up(n: int = 120) -> None:
    """Run every estimator once on a small frame, so that numba's compiling stays out of the times."""
    frame = cell_frames(simulation_config(n, 0.5, "random"), 1, 12345)[0]
    for run in curve_runners(0.99).values():
        run(frame, 0)


# ----------------------------------------------------------------------------- priors


def prior_runners() -> dict[str, peers.Runner]:
    """Ours and SupeRANSAC, uniform and fed the scores (order or probabilities), at confidence 0.99."""
    runners: dict[str, peers.Runner | None] = {
        "ours, uniform": peers.ours("probabilistic", "uniform"),
        "ours, PROSAC by score": peers.ours("probabilistic", "prosac"),
        "ours, guided by score": peers.ours("probabilistic", "guided"),
        "SupeRANSAC, uniform": peers.superansac("uniform"),
        "SupeRANSAC, PROSAC by score": peers.superansac("prosac"),
        "SupeRANSAC, importance by score": peers.superansac("importance"),
        "SupeRANSAC, AR by score": peers.superansac("ar"),
    }
    return {name: run for name, run in runners.items() if run is not None}


def prior_table(n: int, epsilons: Iterable[float], aucs: Iterable[float], preset: str, frames: int, seed: int = 0,
                repeats: int = 1, progress: Callable | None = None) -> list[dict]:
    """Hypotheses, time, success and rotation error of :func:`prior_runners` on the same frames per
    (epsilon, score AUC) cell; rows as dictionaries (``auc`` added)."""
    rows = []
    for eps in epsilons:
        for auc in aucs:
            cell = cell_frames(simulation_config(n, eps, preset, score_auc=auc), frames, seed)
            runners = {(name, 0.99): run for name, run in prior_runners().items()}
            for point in measure_cell(runners, cell, seed, eps, repeats):
                rows.append({**asdict(point), "auc": auc})
            if progress is not None:
                progress(1)
    return rows


def prior_table_markdown(rows: list[dict]) -> str:
    """The prior table as markdown: per (epsilon, AUC), each estimator's median hypotheses and time,
    success, and its time over its own uniform sampler's."""
    lines = ["| eps | score AUC | estimator | median hypotheses | median ms | x own uniform time | success | median rot. deg |",
             "|---|---|---|---|---|---|---|---|"]
    uniform = {(r["epsilon"], r["auc"], r["estimator"].split(",")[0]): r["median_ms"]
               for r in rows if r["estimator"].endswith("uniform")}
    for r in rows:
        base = uniform.get((r["epsilon"], r["auc"], r["estimator"].split(",")[0]), float("nan"))
        lines.append(f"| {r['epsilon']:.1f} | {r['auc']:.2f} | {r['estimator']} | {r['median_hypotheses']:.0f} | "
                     f"{r['median_ms']:.2f} | {r['median_ms'] / base:.2f} | {r['success']:.2f} | {r['median_rot_deg']:.4f} |")
    return "\n".join(lines)


# ----------------------------------------------------------------------------- the figure


def plot_curves(points: list[CurvePoint], path, title: str):
    """Success (with 95 % Wilson bands) and median rotation error against median time per frame,
    one column per epsilon, one line per estimator (points in order of time)."""
    from matplotlib.ticker import FuncFormatter, NullFormatter

    from stereovo.reporting import figure, line_style, plot_success, save_figure

    epsilons = sorted({p.epsilon for p in points})
    names = list(dict.fromkeys(p.estimator for p in points))
    fig = figure((4.2 * len(epsilons), 7.0))
    axes = fig.subplots(2, len(epsilons), squeeze=False)
    for col, eps in enumerate(epsilons):
        top, bottom = axes[0, col], axes[1, col]
        for i, name in enumerate(names):
            pts = sorted((p for p in points if p.epsilon == eps and p.estimator == name), key=lambda p: p.median_ms)
            if not pts:
                continue
            style = line_style(i)
            xs = [p.median_ms for p in pts]
            plot_success(top, xs, [p.success for p in pts], [p.frames for p in pts], name, style)
            bottom.plot(xs, [p.median_rot_deg for p in pts], label=name, lw=1.3, ms=4, **style)
        for ax in (top, bottom):
            ax.set_xscale("log")
            ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _: f"{x:g}"))
            ax.xaxis.set_minor_formatter(NullFormatter())  # log minor labels collide on a narrow range
            ax.grid(True, which="both", alpha=0.3)
        bottom.set_yscale("log")
        top.set_title(f"eps {eps:g}")
        bottom.set_xlabel("median time per frame (ms, log)")
        top.set_ylabel("success (%)")
        bottom.set_ylabel("median rotation error (deg, log)")
    axes[0, 0].legend(fontsize=7, loc="lower right")
    fig.suptitle(title, fontsize=10)
    return save_figure(fig, path)
