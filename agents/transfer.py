"""The transfer matrix: every shipped sampler and the hand-derived ones across match distributions.

Do learned priors transfer to outliers unlike their training data? Each *domain* is a source of
10-frame sequences; each cell is a domain at one contamination, the same frames for every row:

- ``default``: the simulator's default outlier mix (random mismatches, stereo mismatches, a moving
  object), match-score AUC 0.75: the shipped samplers' training distribution (in-domain);
- ``hostile``: the simulator's hostile preset (:mod:`stereovo.simulation.hostile`: independent
  left/right mismatches, duplicates, far clutter, repetitive-texture clusters consistent with a
  wrong motion, Student-t pixel noise), never seen in training;
- ``rendered``: rendered ``car`` drives (1241x376, one moving car, :class:`stereovo.sequences.RenderedSequence`)
  through the ORB front end, the scores its descriptor distances; the front end's own 15-30 %
  outliers raised to the cell's epsilon with wrong temporal matches between real features
  (:func:`stereovo.sequences.contaminate`): outliers a real matcher makes, never seen in training;
- further domains through :func:`register_domain` (a function that yields sequences of frames).

Rows: each shipped sampler through :class:`agents.LearnedEstimator` (one-shot: fixed budgets and
the prior-aware stop; in-frame: fixed budgets batch after batch and its own stop), BANSAC and ARS
with the match scores as priors, PROSAC ordered by match score, and uniform sampling (MSAC), all
with the environments' estimator options (:data:`vo_gym.settings.DEFAULT_ESTIMATOR_OPTIONS`). Points:
success at 4, 16 and 64 hypotheses, and success with mean hypotheses under each row's own stop
(the cap ``cap``; the in-frame samplers' own cap is their training cap of 64). The cap is this
evaluation's compute budget, the same for every row, so a search that reaches it returns its best
model (``fail_at_cap=False``) and is judged against the truth like any other; the core's default
would fail it instead, which asks another question (confident within the cap). Rates carry Wilson
95 % intervals.

Regenerate: ``python -m agents.transfer --jobs 2 --publish`` (about 50 CPU minutes; ``--jobs 2``
splits the domains over two processes; ``--publish`` writes the figure ``docs/img/transfer.png``,
the CSV ``docs/data/transfer.csv``, the table in ``docs/results.md`` and the results of every model
card ``agents/checkpoints/NAME.md``); ``--frames 60`` for a quick look.
"""

from __future__ import annotations

import csv
import time
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, Sequence

import numpy as np

from stereovo.estimation import drop_unread, estimate_motion
from stereovo.metrics import frame_metrics
from stereovo.reporting import wilson_interval
from stereovo.simulation import Sequence as SimSequence
from stereovo.simulation import SimulationConfig
from vo_gym.settings import DEFAULT_ESTIMATOR_OPTIONS

__all__ = ["DOMAINS", "register_domain", "TransferConfig", "run_transfer", "write_transfer", "main"]

FRAMES_PER_SEQUENCE = 10
OWN_STOP = "own stop"

DomainFrames = Callable[[float, int, int], Iterator[list]]
"""``frames(epsilon, seed, sequences)``: ``sequences`` lists of consecutive frames (each with
``prev``, ``curr``, ``camera``, ``scores``, ``index`` and ``truth`` as :class:`stereovo.simulation.Frame`)."""


def simulator_domain(**settings: Any) -> DomainFrames:
    """A domain of simulated 10-frame sequences with the given :class:`SimulationConfig` settings."""

    def frames(epsilon: float, seed: int, sequences: int) -> Iterator[list]:
        config = SimulationConfig(n_frames=FRAMES_PER_SEQUENCE, n_correspondences=500, outlier_ratio=float(epsilon),
                                  **settings)
        for i in range(sequences):
            yield list(SimSequence(config, seed=np.random.SeedSequence([seed, i])))

    return frames


def rendered_domain(preset: str = "car", resolution: str = "kitti", moving_objects: int = 1,
                    n_frames: int = FRAMES_PER_SEQUENCE) -> DomainFrames:
    """A domain of rendered drives through the front end, each frame contaminated to the cell's
    epsilon (:func:`stereovo.sequences.contaminate`). Needs the ``images`` and ``render`` extras;
    without them the first sequence raises the renderer's one-line reason."""

    def frames(epsilon: float, seed: int, sequences: int) -> Iterator[list]:
        from stereovo.sequences import RenderedSequence, contaminate

        for i in range(sequences):
            world, draws = np.random.SeedSequence([seed, i]).spawn(2)
            drive = RenderedSequence(preset, n_frames=n_frames, resolution=resolution, seed=world,
                                     moving_objects=moving_objects)
            rng = np.random.default_rng(draws)
            try:
                yield [contaminate(frame, epsilon, rng) for frame in drive]
            finally:
                drive.close()

    return frames


DOMAINS: dict[str, DomainFrames] = {
    "default": simulator_domain(),
    "hostile": simulator_domain(outliers="hostile"),
    "rendered": rendered_domain(),
}
"""The domains by name; :func:`register_domain` adds one (a user's own data)."""

IN_DOMAIN = "default"


def register_domain(name: str, frames: DomainFrames) -> None:
    """Add a domain: ``frames(epsilon, seed, sequences)`` yields lists of consecutive frames.

    E.g. a user's own labelled sequences: ``register_domain("mine", lambda eps, seed, k: my_sequences(eps, seed, k))``.
    """
    if not isinstance(name, str) or not name or name in DOMAINS:
        raise ValueError(f"domain name must be a new non-empty string, got {name!r} (known: {', '.join(DOMAINS)})")
    if not callable(frames):
        raise ValueError(f"domain {name!r}: frames must be callable, got {type(frames).__name__}")
    DOMAINS[name] = frames


# ----------------------------------------------------------------------------- rows


class ClassicalRow:
    """A core method on one frame at a time, its sampling input from the match scores."""

    def __init__(self, name: str, method: str, inputs: str, budget: int | None, cap: int) -> None:
        self.name, self.method, self.inputs, self.budget, self.cap = name, method, inputs, budget, cap
        options: dict[str, Any] = {"budget": budget, **DEFAULT_ESTIMATOR_OPTIONS}
        if budget is None:  # the cap of the own stop; a budget is the stop itself and reads neither
            options.update(max_iterations=cap, fail_at_cap=False)
        # the environments' recipe where the method reads it (BANSAC and ARS refit every new best anyway)
        self.options = drop_unread(method, options, order=inputs == "order")

    def reset(self) -> None:
        pass

    def estimate(self, frame, rng: np.random.Generator):
        extra: dict[str, Any] = {}
        if self.inputs == "priors":
            extra["priors"] = frame.scores
        elif self.inputs == "order":
            extra["order"] = np.argsort(-frame.scores, kind="stable")
        return estimate_motion(frame.prev, frame.curr, frame.camera, method=self.method, rng=rng, **extra,
                               **self.options)


class LearnedRow:
    """A :class:`agents.LearnedEstimator` over a sequence (it keeps the previous motion)."""

    def __init__(self, estimator) -> None:
        self.estimator = estimator

    def reset(self) -> None:
        self.estimator.reset()

    def estimate(self, frame, rng: np.random.Generator):
        return self.estimator.estimate(frame.prev, frame.curr, frame.camera, frame.scores, rng=rng)


CLASSICAL_ROWS: tuple[tuple[str, str, str], ...] = (
    ("BANSAC (score priors)", "bansac", "priors"),
    ("ARS (score priors)", "ars", "priors"),
    ("PROSAC (by score)", "prosac", "order"),
    ("uniform (MSAC)", "msac", "none"),
)


@dataclass(frozen=True)
class TransferConfig:
    """What the matrix runs (frames a cell: ``sequences * 10``)."""

    domains: tuple[str, ...] = ("default", "hostile", "rendered")
    epsilons: tuple[float, ...] = (0.5, 0.8, 0.9)
    budgets: tuple[int, ...] = (4, 16, 64)
    sequences: int = 30
    seed: int = 7000
    cap: int = 256
    samplers: tuple[str, ...] | None = None  # None: every shipped sampler
    classical: bool = True
    extra: dict[str, Any] = field(default_factory=dict)

    def sampler_names(self) -> tuple[str, ...]:
        from agents.checkpoint import SHIPPED_IN_FRAME_SAMPLERS, SHIPPED_SAMPLERS

        return SHIPPED_IN_FRAME_SAMPLERS + SHIPPED_SAMPLERS if self.samplers is None else self.samplers


def build_rows(config: TransferConfig) -> list[tuple[str, str, str, Any]]:
    """``(sampler, kind, point, row)`` for every row and point; each learned sampler is loaded once."""
    from agents.catalog import ONE_SHOT
    from agents.estimator import LearnedEstimator
    from agents.samplers import load_sampler

    points: list[int | None] = [*config.budgets, None]
    rows = []
    for name in config.sampler_names():
        policy = load_sampler(name)
        for budget in points:
            # the cap of a search's own stop; a one-shot sampler's budget is the core's, which reads no cap
            # (the estimator refuses one), while an in-frame search keeps its cap under a budget too
            cap = {} if budget is not None and policy.kind == ONE_SHOT else {"max_iterations": config.cap,
                                                                               "fail_at_cap": False}
            estimator = LearnedEstimator(policy, budget=budget, **cap)
            rows.append((policy.name, policy.kind, OWN_STOP if budget is None else str(budget), LearnedRow(estimator)))
    if config.classical:
        for label, method, inputs in CLASSICAL_ROWS:
            for budget in points:
                rows.append((label, "classical", OWN_STOP if budget is None else str(budget),
                             ClassicalRow(label, method, inputs, budget, config.cap)))
    return rows


def run_cell(domain: str, epsilon: float, config: TransferConfig, rows, progress=None) -> list[dict[str, Any]]:
    """Every row on the cell's frames; one result dict per (sampler, point)."""
    if domain not in DOMAINS:
        raise ValueError(f"unknown domain {domain!r}; known: {', '.join(DOMAINS)}")
    # a cell's frames depend on the seed, the domain's name and the contamination alone
    seed = int(np.random.SeedSequence([config.seed, zlib.crc32(domain.encode()), round(1000 * epsilon)]).generate_state(1)[0])
    tallies = [{"success": 0, "frames": 0, "hypotheses": 0, "time_s": []} for _ in rows]
    for k, sequence in enumerate(DOMAINS[domain](epsilon, seed, config.sequences)):
        for (_, _, _, row), tally in zip(rows, tallies):
            row.reset()
            rng = np.random.default_rng([seed, k])  # the same draws' stream for every row of a sequence
            for frame in sequence:
                est = row.estimate(frame, rng)
                tally["success"] += int(frame_metrics(est, frame.truth).success)
                tally["frames"] += 1
                tally["hypotheses"] += int(est.n_hypotheses)
                tally["time_s"].append(est.time_s)
        if progress is not None:
            progress.update(1)
    out = []
    for (sampler, kind, point, _), tally in zip(rows, tallies):
        n = tally["frames"]
        low, high = wilson_interval(tally["success"], n)
        out.append({"domain": domain, "epsilon": epsilon, "sampler": sampler, "kind": kind, "point": point,
                    "seed": config.seed, "cap": config.cap,
                    "frames": n, "successes": tally["success"], "success": tally["success"] / n,
                    "ci_low": float(low), "ci_high": float(high), "mean_hypotheses": tally["hypotheses"] / n,
                    "median_ms": 1e3 * float(np.median(tally["time_s"]))})
    return out


def run_transfer(config: TransferConfig, progress: bool = True) -> list[dict[str, Any]]:
    """The whole matrix: one result dict per (domain, epsilon, sampler, point)."""
    import torch
    from tqdm import tqdm

    torch.set_num_threads(1)  # one frame's forward pass is small: threads only contend
    rows = build_rows(config)
    cells = [(d, e) for d in config.domains for e in config.epsilons]
    results: list[dict[str, Any]] = []
    with tqdm(total=len(cells) * config.sequences, desc="transfer matrix", unit="sequence",
              disable=not progress) as bar:
        for domain, epsilon in cells:
            bar.set_postfix_str(f"{domain} eps {epsilon}")
            results += run_cell(domain, epsilon, config, rows, bar)
    return results


# ----------------------------------------------------------------------------- reports

FIELDS = ("domain", "epsilon", "sampler", "kind", "point", "frames", "successes", "success", "ci_low", "ci_high",
          "mean_hypotheses", "median_ms", "seed", "cap")
DEFAULTS = TransferConfig()
BEGIN, END = "<!-- transfer:begin -->", "<!-- transfer:end -->"
PUBLISHED = {"figure": Path("docs/img/transfer.png"), "csv": Path("docs/data/transfer.csv"),
             "results": Path("docs/results.md"), "cards": Path("agents/checkpoints")}


def read_results(path: str | Path) -> list[dict[str, Any]]:
    """The rows of a ``transfer.csv``, numbers as numbers."""
    rows = []
    with open(path, newline="") as f:
        for r in csv.DictReader(f):
            for key in ("epsilon", "success", "ci_low", "ci_high", "mean_hypotheses", "median_ms"):
                r[key] = float(r[key])
            for key in ("frames", "successes"):
                r[key] = int(r[key])
            for key, default in (("seed", DEFAULTS.seed), ("cap", DEFAULTS.cap)):
                r[key] = int(r.get(key) or default)
            rows.append(r)
    return rows


def _cell(r: dict[str, Any] | None, hypotheses: bool = False) -> str:
    if r is None:
        return ""
    text = f"{100 * r['success']:.1f} ({100 * r['ci_low']:.0f}-{100 * r['ci_high']:.0f})"
    return f"{text} at {r['mean_hypotheses']:.1f}" if hypotheses else text


def transfer_markdown(results: Sequence[dict[str, Any]], command: str) -> str:
    """One table per domain: success (%) with its Wilson 95 % interval at each budget, and under
    the own stop with the mean hypotheses it drew."""
    index = {(r["domain"], r["epsilon"], r["sampler"], r["point"]): r for r in results}
    budgets = sorted({r["point"] for r in results if r["point"] != OWN_STOP}, key=int)
    samplers = list(dict.fromkeys(r["sampler"] for r in results))
    frames = sorted({r["frames"] for r in results})
    lines = [f"Regenerate: `{command}`. Frames a cell: {', '.join(map(str, frames))}; success % "
             "(Wilson 95 % interval); own stop: success at mean hypotheses.", ""]
    for domain in dict.fromkeys(r["domain"] for r in results):
        lines += [f"#### {domain}" + (" (in-domain)" if domain == IN_DOMAIN else " (transfer)"), "",
                  "| sampler | eps | " + " | ".join(f"{b} hypotheses" for b in budgets) + " | own stop |",
                  "|---|---|" + "---|" * (len(budgets) + 1)]
        for sampler in samplers:
            for eps in sorted({r["epsilon"] for r in results if r["domain"] == domain}):
                cells = [_cell(index.get((domain, eps, sampler, b))) for b in budgets]
                own = _cell(index.get((domain, eps, sampler, OWN_STOP)), hypotheses=True)
                lines.append(f"| {sampler} | {eps:g} | " + " | ".join(cells) + f" | {own} |")
        lines.append("")
    return "\n".join(lines)


def write_csv(results: Sequence[dict[str, Any]], path: str | Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=FIELDS)
        writer.writeheader()
        for r in results:
            writer.writerow({k: (f"{r[k]:.6g}" if isinstance(r[k], float) else r[k]) for k in FIELDS})
    return path


def plot_transfer(results: Sequence[dict[str, Any]], path: str | Path) -> Path:
    """Success at each budget (bars with Wilson 95 % error bars), one panel per domain and eps,
    and under the own stop against mean hypotheses (points with the same intervals)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    domains = list(dict.fromkeys(r["domain"] for r in results))
    epsilons = sorted({r["epsilon"] for r in results})
    samplers = list(dict.fromkeys(r["sampler"] for r in results))
    budgets = sorted({r["point"] for r in results if r["point"] != OWN_STOP}, key=int)
    index = {(r["domain"], r["epsilon"], r["sampler"], r["point"]): r for r in results}
    fig, axes = plt.subplots(2 * len(domains), len(epsilons), figsize=(5.2 * len(epsilons), 4.6 * 2 * len(domains)),
                             squeeze=False)
    colours = plt.get_cmap("tab10").colors
    y = np.arange(len(samplers))
    height = 0.8 / max(len(budgets), 1)
    for i, domain in enumerate(domains):
        for j, eps in enumerate(epsilons):
            ax = axes[2 * i, j]
            for b, budget in enumerate(budgets):
                rows = [index.get((domain, eps, s, budget)) for s in samplers]
                rate = np.array([np.nan if r is None else 100 * r["success"] for r in rows])
                err = np.array([[0, 0] if r is None else [100 * (r["success"] - r["ci_low"]),
                                                          100 * (r["ci_high"] - r["success"])] for r in rows]).T
                ax.barh(y + (b - (len(budgets) - 1) / 2) * height, rate, height, xerr=err, capsize=2,
                        color=colours[b], label=f"{budget} hypotheses", error_kw={"elinewidth": 0.8})
            ax.set_yticks(y, samplers, fontsize=7)
            ax.invert_yaxis()
            ax.set_xlim(0, 100)
            ax.set_xlabel("success (%), 95 % Wilson interval")
            ax.set_title(f"{domain}, eps {eps:g}: fixed budgets", fontsize=9)
            ax.grid(axis="x", alpha=0.3)
            if j == 0:
                ax.legend(fontsize=7, loc="lower right")
            ax = axes[2 * i + 1, j]
            for s, sampler in enumerate(samplers):
                r = index.get((domain, eps, sampler, OWN_STOP))
                if r is None:
                    continue
                err = [[100 * (r["success"] - r["ci_low"])], [100 * (r["ci_high"] - r["success"])]]
                ax.errorbar([r["mean_hypotheses"]], [100 * r["success"]], yerr=err, fmt="os^vD<>ph*"[s % 10],
                            color=plt.get_cmap("tab20").colors[s % 20], capsize=3, label=sampler)
            ax.set_xscale("log")
            ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())  # minor labels overlap on short ranges
            ax.set_ylim(0, 102)
            ax.set_xlabel("mean hypotheses per frame (own stop)")
            ax.set_ylabel("success (%), 95 % Wilson interval")
            ax.set_title(f"{domain}, eps {eps:g}: own stop", fontsize=9)
            ax.grid(alpha=0.3)
            if j == 0:
                ax.legend(fontsize=6, loc="lower left")
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def regenerate_command(results: Sequence[dict[str, Any]]) -> str:
    """The command that reproduces ``results`` (their frames, domains, contaminations, budgets,
    seed and cap; the defaults left out)."""
    parts = ["python -m agents.transfer --jobs 2 --publish"]
    frames = max(r["frames"] for r in results)
    if frames != DEFAULTS.sequences * FRAMES_PER_SEQUENCE:
        parts.append(f"--frames {frames}")
    domains = ",".join(dict.fromkeys(r["domain"] for r in results))
    if domains != ",".join(DEFAULTS.domains):
        parts.append(f"--domains {domains}")
    epsilons = ",".join(f"{e:g}" for e in sorted({r["epsilon"] for r in results}))
    if epsilons != ",".join(f"{e:g}" for e in DEFAULTS.epsilons):
        parts.append(f"--epsilons {epsilons}")
    budgets = ",".join(sorted({r["point"] for r in results if r["point"] != OWN_STOP}, key=int))
    if budgets != ",".join(map(str, DEFAULTS.budgets)):
        parts.append(f"--budgets {budgets}")
    for key in ("seed", "cap"):
        value = results[0].get(key, getattr(DEFAULTS, key))
        if value != getattr(DEFAULTS, key):
            parts.append(f"--{key} {value}")
    return " ".join(parts)


def model_card_block(results: Sequence[dict[str, Any]], sampler: str, command: str) -> str:
    """A model card's transfer results: this sampler on every domain and contamination."""
    mine = [r for r in results if r["sampler"] == sampler]
    if not mine:
        return f"Not in the transfer matrix of `{command}`."
    index = {(r["domain"], r["epsilon"], r["point"]): r for r in mine}
    budgets = sorted({r["point"] for r in mine if r["point"] != OWN_STOP}, key=int)
    frames = sorted({r["frames"] for r in mine})
    uniform = {(r["domain"], r["epsilon"]): r for r in results if r["sampler"] == "uniform (MSAC)" and r["point"] == "16"}
    lines = [f"Regenerate: `{command}` ({', '.join(map(str, frames))} frames a cell; success % with its Wilson 95 % "
             "interval; own stop: success at mean hypotheses; uniform MSAC at 16 hypotheses for scale).", "",
             "| domain | eps | " + " | ".join(f"{b} hypotheses" for b in budgets) + " | own stop | uniform, 16 |",
             "|---|---|" + "---|" * (len(budgets) + 2)]
    for domain in dict.fromkeys(r["domain"] for r in mine):
        label = f"{domain} ({'in-domain' if domain == IN_DOMAIN else 'transfer'})"
        for eps in sorted({r["epsilon"] for r in mine if r["domain"] == domain}):
            cells = [_cell(index.get((domain, eps, b))) for b in budgets]
            lines.append(f"| {label} | {eps:g} | " + " | ".join(cells)
                         + f" | {_cell(index.get((domain, eps, OWN_STOP)), hypotheses=True)} | "
                         + f"{_cell(uniform.get((domain, eps)))} |")
    return "\n".join(lines)


def replace_block(text: str, block: str, where: str) -> str:
    """``text`` with the part between :data:`BEGIN` and :data:`END` replaced by ``block``."""
    if text.count(BEGIN) != 1 or text.count(END) != 1 or text.index(BEGIN) > text.index(END):
        raise ValueError(f"{where}: needs one {BEGIN} ... {END} block")
    head, rest = text.split(BEGIN)
    _, tail = rest.split(END)
    return f"{head}{BEGIN}\n{block.strip()}\n{END}{tail}"


def publish(results: Sequence[dict[str, Any]], root: str | Path = ".") -> list[Path]:
    """Write the figure, the CSV, the table of ``docs/results.md`` and every model card's results."""
    root = Path(root)
    command = regenerate_command(results)
    paths = [plot_transfer(results, root / PUBLISHED["figure"]), write_csv(results, root / PUBLISHED["csv"])]
    doc = root / PUBLISHED["results"]
    doc.write_text(replace_block(doc.read_text(), transfer_markdown(results, command), str(doc)))
    paths.append(doc)
    for card in sorted((root / PUBLISHED["cards"]).glob("*.md")):
        card.write_text(replace_block(card.read_text(), model_card_block(results, card.stem, command), str(card)))
        paths.append(card)
    return paths


def write_transfer(results: Sequence[dict[str, Any]], out: str | Path, command: str,
                   figure: str | Path | None = None) -> list[Path]:
    """``transfer.csv``, ``transfer.md`` and ``transfer.png`` (or ``figure``) under ``out``."""
    out = Path(out)
    paths = [write_csv(results, out / "transfer.csv")]
    (out / "transfer.md").write_text(transfer_markdown(results, command))
    paths.append(out / "transfer.md")
    paths.append(plot_transfer(results, figure or out / "transfer.png"))
    return paths


def merge(parts: Iterable[Sequence[dict[str, Any]]]) -> list[dict[str, Any]]:
    """Results of several runs (e.g. one per domain), a later run's row replacing an earlier one's."""
    merged: dict[tuple, dict[str, Any]] = {}
    for part in parts:
        for r in part:
            merged[(r["domain"], r["epsilon"], r["sampler"], r["point"])] = r
    # the domains in the registry's order (parts split them round-robin), the rows of each as run
    rank = {name: i for i, name in enumerate(DOMAINS)}
    return sorted(merged.values(), key=lambda r: rank.get(r["domain"], len(rank)))


def _floats(text: str, name: str, kind=float) -> tuple:
    try:
        values = tuple(kind(x) for x in text.split(","))
    except ValueError:
        raise SystemExit(f"transfer: --{name} must be a comma-separated list, got {text!r}") from None
    return values


def main(argv: list[str] | None = None) -> int:
    """``python -m agents.transfer --out runs/transfer [--frames 300] [--jobs 2]``."""
    import argparse
    import subprocess
    import sys

    parser = argparse.ArgumentParser(description="transfer matrix of the shipped samplers across match distributions")
    parser.add_argument("--out", default="runs/transfer")
    parser.add_argument("--frames", type=int, default=300, help="frames a cell (a multiple of 10; default 300)")
    parser.add_argument("--domains", default="default,hostile,rendered")
    parser.add_argument("--epsilons", default="0.5,0.8,0.9")
    parser.add_argument("--budgets", default="4,16,64")
    parser.add_argument("--samplers", default=None, help="comma-separated sampler names or paths (default: every shipped one)")
    parser.add_argument("--no-classical", action="store_true", help="the learned rows only")
    parser.add_argument("--cap", type=int, default=256, help="hypotheses cap of the own-stop rows (default 256)")
    parser.add_argument("--seed", type=int, default=7000)
    parser.add_argument("--jobs", type=int, default=1, help="processes, one or more domains each (default 1)")
    parser.add_argument("--figure", default=None, help="where the figure goes (default OUT/transfer.png)")
    parser.add_argument("--merge", nargs="+", metavar="CSV", help="merge these transfer.csv files into --out; runs nothing")
    parser.add_argument("--publish", action="store_true",
                        help="also write docs/img/transfer.png, docs/data/transfer.csv, the table in docs/results.md "
                             "and the model cards' results (run from the repository root)")
    parser.add_argument("--no-progress", action="store_true")
    args = parser.parse_args(argv)

    def report(results) -> None:
        command = regenerate_command(results)
        for path in write_transfer(results, args.out, command, args.figure):
            print(path)
        if args.publish:
            for path in publish(results):
                print(path)

    if args.merge:
        report(merge(read_results(p) for p in args.merge))
        return 0
    if args.frames < FRAMES_PER_SEQUENCE or args.frames % FRAMES_PER_SEQUENCE:
        parser.error(f"--frames must be a positive multiple of {FRAMES_PER_SEQUENCE}, got {args.frames}")
    if args.cap < 1:
        parser.error(f"--cap must be >= 1, got {args.cap}")
    domains = tuple(d for d in args.domains.split(",") if d)
    unknown = [d for d in domains if d not in DOMAINS]
    if unknown:
        parser.error(f"unknown domain(s) {', '.join(unknown)}; known: {', '.join(DOMAINS)}")
    epsilons = _floats(args.epsilons, "epsilons")
    if not all(0 <= e < 1 for e in epsilons):
        parser.error(f"--epsilons must lie in [0, 1), got {args.epsilons}")
    budgets = _floats(args.budgets, "budgets", int)
    if not all(b >= 1 for b in budgets):
        parser.error(f"--budgets must be >= 1, got {args.budgets}")
    if args.jobs > 1 and len(domains) > 1:
        # one process per group of domains, merged afterwards: the frames depend on the seeds alone
        groups = [domains[i::args.jobs] for i in range(min(args.jobs, len(domains)))]
        rest = [a for a in (argv if argv is not None else sys.argv[1:])]
        procs, outs = [], []
        for i, group in enumerate(groups):
            sub_out = Path(args.out) / f"part-{i}"
            outs.append(sub_out / "transfer.csv")
            cli = _without([a for a in rest if a != "--publish"], ("--jobs", "--out", "--domains", "--figure")) + [
                "--out", str(sub_out), "--domains", ",".join(group), "--no-progress" if i else ""]
            procs.append(subprocess.Popen([sys.executable, "-m", "agents.transfer", *[c for c in cli if c]]))
        codes = [p.wait() for p in procs]
        if any(codes):
            print(f"transfer: a part failed (exit codes {codes})", file=sys.stderr)
            return 1
        report(merge(read_results(p) for p in outs))
        return 0
    config = TransferConfig(domains=domains, epsilons=epsilons, budgets=budgets,
                            sequences=args.frames // FRAMES_PER_SEQUENCE, seed=args.seed, cap=args.cap,
                            samplers=None if args.samplers is None else tuple(args.samplers.split(",")),
                            classical=not args.no_classical)
    start = time.time()
    results = run_transfer(config, progress=not args.no_progress)
    report(results)
    print(f"transfer: {len(results)} rows in {(time.time() - start) / 60:.1f} min")
    return 0


def _without(argv: list[str], options: tuple[str, ...]) -> list[str]:
    """``argv`` without the given options and their values (``--x v`` or ``--x=v``)."""
    out, skip = [], False
    for a in argv:
        if skip:
            skip = False
            continue
        if a in options:
            skip = True
            continue
        if any(a.startswith(o + "=") for o in options):
            continue
        out.append(a)
    return out


if __name__ == "__main__":
    raise SystemExit(main())
