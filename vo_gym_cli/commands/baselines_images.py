"""``vo-gym baselines --source rendered[:PRESET]``: the classical family on rendered stereo images.

A sequence is rendered (``--seed``, ``--resolution``, ``--frames`` pairs) and matched by the image
front end once; every method then runs on every pair with its own stop
(:mod:`stereovo.benchmark.on_images`). The run keeps no journal: a non-empty ``--out`` is replaced
with ``--overwrite`` only, and ``--resume`` is refused. The contamination is the front end's, measured by the
rendering's per-match ground truth, not chosen. Success is within 1 deg / 5 cm of the true
motion, with Wilson 95 % intervals over the pairs; precision and recall are those of the returned
inliers against the labels. KITTI sequences have no per-match labels, so they are refused here
(``vo-gym vo --source kitti:PATH`` measures a trajectory on them).

Writes to ``--out``: ``frames.csv`` (one row per pair and method), ``summary.json``, ``summary.md``
(the table printed here) and ``success_vs_time.png`` (unless ``--no-plots``).
"""

from __future__ import annotations

import argparse
import csv
import json
import platform

from vo_gym_cli.commands.common import UsageError, open_run_folder, render_pairs, require_extra


def run_on_images(args: argparse.Namespace) -> int:
    """The ``--source`` branch of ``vo-gym baselines`` (see the module doc)."""
    from stereovo import benchmark as bm
    from stereovo.benchmark.on_images import plot_summary, run_on_frames, summarise, summary_markdown
    from stereovo.sequences.sources import parse_source

    kind, named = parse_source(args.source)
    if kind != "rendered":
        raise UsageError(f"--source {args.source!r}: baselines needs per-match ground truth, which rendered "
                         "sequences have (rendered or rendered:PRESET); run vo-gym vo --source for a KITTI trajectory")
    if args.preset is not None and named.get("preset", args.preset) != args.preset:
        raise UsageError(f"--preset {args.preset} contradicts --source {args.source}")
    preset = named.get("preset", args.preset or "car")
    args.frames = args.frames or 40
    args.resolution = args.resolution or "kitti"
    require_extra("images", "cv2", context=f"--source {args.source}")
    require_extra("render", "moderngl", "glcontext", context=f"--source {args.source}")
    options = {} if args.max_iterations is None else {"max_iterations": args.max_iterations}
    try:
        estimators = bm.classical_estimators(args.methods, **options)
    except ValueError as err:
        raise UsageError(f"--methods: {err}") from None
    out = open_run_folder(args, resumable=False)  # check_options_apply refused --resume
    frames = _render(args, preset)
    names = [name for name, _ in estimators]
    print(f"vo-gym baselines: {len(names)} methods on {len(frames)} rendered pairs ({preset}, {args.resolution}, "
          f"seed {args.seed}); outlier ratio of the matches {_ratio_range(frames)}", flush=True)
    bar = None
    if not args.no_progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=len(frames), desc="methods on pairs", unit="pair")
    bm.warm_up_estimators(estimators)
    rows = run_on_frames(frames, estimators, args.seed, advance=None if bar is None else bar.update)
    if bar is not None:
        bar.close()
    summary = summarise(rows)
    title = f"The classical family on {len(frames)} rendered pairs ({preset}, {args.resolution}, seed {args.seed})"
    table = summary_markdown(summary, title)
    print(table)
    with open(out / "frames.csv", "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    settings = {"source": args.source, "preset": preset, "resolution": args.resolution, "frames": len(frames),
                "seed": args.seed, "methods": names, "max_iterations": args.max_iterations,
                "python": platform.python_version()}
    (out / "summary.json").write_text(json.dumps({"settings": settings, "summary": summary}, indent=2) + "\n")
    (out / "summary.md").write_text(table)
    written = ["frames.csv", "summary.json", "summary.md"]
    if not args.no_plots:
        plot_summary(out / f"success_vs_time.{args.plot_format}", summary, title)
        written.append(f"success_vs_time.{args.plot_format}")
    print(f"wrote {', '.join(written)} to {out}")
    return 0


def _render(args: argparse.Namespace, preset: str) -> list:
    bar = None
    if not args.no_progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=args.frames, desc="rendering + matching", unit="pair")
    try:
        frames, _ = render_pairs(args.source, preset, args.frames, args.seed, args.resolution,
                                 advance=None if bar is None else bar.update)
    finally:
        if bar is not None:
            bar.close()
    return frames


def _ratio_range(frames: list) -> str:
    ratios = [float(f.truth.outlier_ratio) for f in frames]
    return f"{min(ratios):.2f}-{max(ratios):.2f}"
