"""``vo-gym vo``: stereo visual odometry over one sequence: simulated matches (default), or images
through the front end (``--source rendered[:PRESET]`` or ``--source kitti:PATH[:SEQ]``).

Writes to ``--out``: ``trajectory_est.tum``, ``trajectory_true.tum``,
``trajectory_est.kitti.txt``, ``trajectory_true.kitti.txt``, ``frames.csv``
(one row per frame), ``covariances.npy``, ``odometry.png`` and ``summary.json``;
prints a summary table. ``covariances.npy`` holds one ``(6, 6)`` covariance per
frame (``(F, 6, 6)`` float64, ``numpy.load``), row k for the motion of frame
pair k: the covariance of the error ``(log(R_est R_true^T), t_est - t_true)``,
rotation first (rad) then translation (m), as
:attr:`stereovo.estimation.MotionEstimate.covariance`; NaN on a failed frame. The TUM files load directly in evo (``evo_ape tum trajectory_true.tum
trajectory_est.tum --align``).

A KITTI sequence without ground-truth poses gets the estimated trajectory only (``trajectory_est.*``,
``frames.csv`` with each frame's success, matches and inliers, ``odometry.png``, ``summary.json``).
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any, Iterator

from agents.catalog import IN_FRAME_SAMPLERS, ONE_SHOT_SAMPLERS
from vo_gym_cli.commands.arguments import (
    DETECTORS,
    OUTLIER_PRESETS,
    PRESETS,
    bounded_int,
    finite_float,
    output_path,
    parse_source,
    positive_int,
    seed,
)
from vo_gym_cli.commands.common import RunStart, UsageError, check_output_dir, require_extra, score_inputs


class _LazyMethodChoices:
    """argparse ``choices`` that consults the estimator registry only when used.

    Building the parser (``vo-gym --help``) then imports no estimation code;
    validation and help text still list exactly what ``available_methods()`` offers.
    """

    def _names(self) -> list[str]:
        from stereovo.estimation import available_methods

        return list(available_methods())

    def __contains__(self, item: object) -> bool:
        return item in self._names()

    def __iter__(self) -> Iterator[str]:
        return iter(self._names())

    def __len__(self) -> int:
        return len(self._names())


def parse_outliers(text: str) -> float | tuple[float, float]:
    """``"0.5"`` -> 0.5; ``"0.3:0.9"`` -> (0.3, 0.9). Ratios must lie in [0, 1)."""
    parts = text.split(":")
    if len(parts) > 2:
        raise argparse.ArgumentTypeError(f"outlier ratio {text!r}: expected a number or a range lo:hi")
    try:
        values = [float(p) for p in parts]
    except ValueError:
        raise argparse.ArgumentTypeError(f"outlier ratio {text!r} is not a number or a range lo:hi") from None
    for v in values:
        if not 0.0 <= v < 1.0:
            raise argparse.ArgumentTypeError(f"outlier ratio {v:g} must lie in [0, 1)")
    if len(values) == 2:
        if values[0] > values[1]:
            raise argparse.ArgumentTypeError(f"outlier range {text!r} must have lo <= hi")
        return values[0], values[1]
    return values[0]


def add_parser(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--source", type=parse_source, default=None, metavar="rendered[:PRESET]|kitti:PATH[:SEQ]",
        help="run on images through the front end instead of simulated matches: a rendered sequence "
             "(needs the 'images' and 'render' extras; PRESET car or free, else --preset) or a KITTI odometry "
             "sequence on disk (PATH a dataset folder with sequences/SEQ/, default SEQ 00, or one sequence's "
             "folder; needs the 'images' extra); --outliers, --outlier-preset, --n and --auc apply to simulated "
             "matches only and are refused with it (default: simulated matches)",
    )
    parser.add_argument("--detector", default=None, choices=list(DETECTORS),
                        help="the front end's keypoints and descriptors with --source: orb (the default), sift or "
                             "akaze (OpenCV's contrib build, which the 'images' extra installs)")
    parser.add_argument("--resolution", default=None, choices=["kitti", "vga"],
                        help="a rendered source's image size: kitti (1241x376, the default) or vga (640x480)")
    parser.add_argument("--preset", default=None, choices=list(PRESETS),
                        help="motion preset of simulated matches or a rendered source (default car; "
                             "a KITTI sequence has its own motion)")
    parser.add_argument("--frames", type=positive_int("--frames"), default=300,
                        help="frame pairs to simulate or render (a KITTI sequence: at most this many, from its start)")
    parser.add_argument(
        "--outliers", type=parse_outliers, default=None, metavar="EPS|LO:HI",
        help="outlier ratio, fixed or drawn per frame from a range (0.3:0.9) (default 0.5)",
    )
    parser.add_argument(
        "--outlier-preset", default=None, choices=list(OUTLIER_PRESETS),
        help="the kinds of match errors: the simulator's default mix (the default), or hostile (independent "
             "left/right mismatches, duplicates, far clutter, repetitive texture, Student-t pixel noise)",
    )
    parser.add_argument("--noise", type=finite_float("--noise", 1e-3, 1e3), default=0.5,
                        help="pixel noise sigma (px), in [0.001, 1000]")
    parser.add_argument("--n", type=bounded_int("--n", 3), default=None,
                        help="correspondences per frame (>= 3; default 500)")
    parser.add_argument("--auc", type=finite_float("--auc"), default=None,
                        help="match-score ROC AUC in [0.5, 1) (0.5 = uninformative; default 0.75)")
    parser.add_argument(
        "--method", default="probabilistic", choices=_LazyMethodChoices(),
        help="estimator; PROSAC-style methods sample by the match scores' order, guided MLESAC by the "
             "scores calibrated to inlier probabilities (its gamma_i)",
    )
    parser.add_argument("--agent", default=None, metavar="NAME|PATH",
                        help="a learned sampler: a one-shot one sets the method's sampling weights each frame "
                             f"({', '.join(ONE_SHOT_SAMPLERS)}); an in-frame one runs the method's search batch by "
                             f"batch and stops it ({', '.join(IN_FRAME_SAMPLERS)}); or a .pt checkpoint of "
                             "either kind (default: none)")
    parser.add_argument("--seed", type=seed, default=0, help="seed of the simulation and of the estimator stream")
    parser.add_argument(
        "--out", type=output_path(), default=Path("runs/vo"),
        help="output folder: trajectories (TUM, KITTI), frames.csv, covariances.npy (one 6x6 motion covariance "
        "per frame, rotation rad then translation m; NaN where the estimate failed), odometry.png, summary.json",
    )
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")


class _LearnedSampling:
    """A learned sampler's per-frame sampling input: its logits on the frame's features.

    The features carry the constant-velocity prediction of the last successful estimate, as in
    the environment the sampler was trained in (none before the first success).
    """

    def __init__(self, policy: Any, noise_sigma: float, order: bool) -> None:
        self.policy, self.noise_sigma, self.order = policy, noise_sigma, order
        self.previous_motion: tuple | None = None

    def __call__(self, frame: Any):
        import numpy as np

        from vo_gym.features import compute_features

        features = compute_features(frame.prev, frame.curr, frame.scores, frame.camera, self.noise_sigma,
                                    self.previous_motion)
        logits = np.asarray(self.policy.act({"features": features, "mask": np.ones(frame.n, dtype=np.int8)}),
                            dtype=np.float64)
        if self.order:
            return np.argsort(-logits, kind="stable")
        if logits.size == 0:  # a frame without matches (a blank image): no weights; the estimate fails the frame
            return logits
        return np.exp(logits - logits.max())  # guided-sampling weights, softmax up to a constant

    def observe(self, frame: Any, estimate: Any) -> None:
        if estimate.ok:
            self.previous_motion = (estimate.rotation, estimate.translation)


def _json_safe(value: Any) -> Any:
    """JSON has no NaN/inf: write them as null."""
    if isinstance(value, dict):
        return {k: _json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_safe(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if hasattr(value, "item"):  # numpy scalars
        return _json_safe(value.item())
    return value


def _summary_lines(s: dict[str, Any]) -> list[str]:
    def f(x: float, spec: str) -> str:
        return "n/a" if x is None or (isinstance(x, float) and math.isnan(x)) else format(x, spec)

    kitti = (
        f"{f(s['kitti_t_percent'], '.3f')} %  /  {f(s['kitti_r_deg_per_m'], '.5f')} deg/m"
        f"  ({s['kitti_segments']} segments)"
        if s["kitti_segments"]
        else f"n/a (path {s['path_length_m']:.0f} m shorter than the shortest segment)"
    )
    table = [
        ("method", s["method"]),
        ("frames", f"{s['frames']}  ({s['failed_frames']} failed: previous motion reused)"),
        ("success rate", f"{f(100 * s['success_rate'], '.1f')} %"),
        ("median rotation error", f"{f(s['median_rot_err_deg'], '.4f')} deg"),
        ("median translation error", f"{f(s['median_trans_err_m'], '.4f')} m"),
        ("mean inlier precision / recall", f"{f(s['mean_precision'], '.3f')} / {f(s['mean_recall'], '.3f')}"),
        ("median hypotheses", f"{f(s['median_hypotheses'], '.0f')}"),
        ("median time per frame", f"{f(1e3 * s['median_time_s'], '.2f')} ms"),
        ("path length", f"{s['path_length_m']:.1f} m"),
        ("ATE raw / aligned", f"{f(s['ate_raw_m'], '.3f')} m / {f(s['ate_aligned_m'], '.3f')} m"),
        ("RPE (1 frame) trans / rot", f"{f(s['rpe_trans_m'], '.4f')} m / {f(s['rpe_rot_deg'], '.4f')} deg"),
        ("KITTI drift trans / rot", kitti),
    ]
    width = max(len(k) for k, _ in table)
    return [f"  {k:<{width}}  {v}" for k, v in table]


def _sampling(args: argparse.Namespace, noise_sigma: float) -> dict[str, Any]:
    """``priors_fn`` / ``order_fn`` / ``on_estimate`` (one-shot sampler, scores) or ``estimate_fn``
    (in-frame sampler) of ``run_odometry`` for ``--method`` and ``--agent``; ``noise_sigma`` (px) is
    what the sampler's features assume."""
    from stereovo.estimation import method_spec

    needs = method_spec(args.method).inputs
    if args.agent is None:
        return score_inputs(args.method)
    if needs == "none":
        raise UsageError(f"--agent {args.agent}: method {args.method!r} does not sample hypotheses, so a learned "
                         "sampler has no role in it; pick a sampling method (e.g. --method msac)")
    from agents.checkpoint import IN_FRAME
    from agents.samplers import load_sampler

    try:
        policy = load_sampler(args.agent)
    except (ValueError, FileNotFoundError) as err:
        raise UsageError(f"--agent: {err}") from None
    if policy.kind == IN_FRAME:
        from agents.estimator import LearnedEstimator

        try:
            estimator = LearnedEstimator(policy, method=args.method, noise_sigma=noise_sigma)
        except ValueError as err:
            raise UsageError(f"--agent {args.agent}: {err}") from None

        def estimate(frame: Any, rng: Any) -> Any:
            return estimator.estimate(frame.prev, frame.curr, frame.camera, frame.scores, rng=rng)

        return {"estimate_fn": estimate}
    sampling = _LearnedSampling(policy, noise_sigma, order=needs == "order")
    key = "order_fn" if needs == "order" else "priors_fn"
    return {key: sampling, "on_estimate": sampling.observe}


# SimulationConfig's field -> the flag that sets it.
_CONFIG_FLAGS = {"preset": "--preset", "n_frames": "--frames", "n_correspondences": "--n", "noise_sigma": "--noise",
                 "outlier_ratio": "--outliers", "outliers": "--outlier-preset", "score_auc": "--auc"}


# The options of simulated matches only (their flags), and their defaults: given with --source, they
# would be ignored, so they are refused instead.
_SIMULATED_ONLY = {"outliers": "--outliers", "outlier_preset": "--outlier-preset", "n": "--n", "auc": "--auc"}
_SIMULATED_DEFAULTS = {"outliers": 0.5, "outlier_preset": "default", "n": 500, "auc": 0.75, "preset": "car"}


def check_source_options(args: argparse.Namespace) -> None:
    """Refuse options the chosen input would ignore, and fill in the defaults of those it reads.

    Raises:
        UsageError: a simulated-matches option with ``--source``; ``--resolution`` without a rendered
            source; ``--preset`` with a KITTI source or against the preset a ``rendered:PRESET`` names.
    """
    from stereovo.sequences.sources import parse_source as parse

    if args.source is None:
        if args.resolution is not None:
            raise UsageError(f"--resolution {args.resolution} applies to a rendered --source only, not to "
                             "simulated matches")
        if args.detector is not None:
            raise UsageError(f"--detector {args.detector} applies to an image --source only, not to simulated "
                             "matches")
        for dest, default in _SIMULATED_DEFAULTS.items():
            if getattr(args, dest) is None:
                setattr(args, dest, default)
        return
    given = [(flag, getattr(args, dest)) for dest, flag in _SIMULATED_ONLY.items() if getattr(args, dest) is not None]
    if given:
        flag, value = given[0]
        shown = ":".join(f"{v:g}" for v in value) if isinstance(value, tuple) else value
        raise UsageError(f"{flag} {shown} applies to simulated matches only, not to --source {args.source}")
    kind, named = parse(args.source)
    if kind != "rendered":
        # --preset also sets the simulated drive; --resolution is the rendering's alone
        for flag, value, owners in (("--resolution", args.resolution, "a rendered --source"),
                                    ("--preset", args.preset, "a rendered --source or simulated matches")):
            if value is not None:
                raise UsageError(f"{flag} {value} applies to {owners}, not to --source {args.source}")
        return
    if args.preset is not None and named.get("preset", args.preset) != args.preset:
        raise UsageError(f"--preset {args.preset} contradicts --source {args.source}")
    args.resolution = args.resolution or "kitti"
    args.preset = args.preset or "car"


def run(args: argparse.Namespace) -> int:
    check_source_options(args)
    if args.source is not None:
        return _run_source(args)
    from stereovo.odometry import run_odometry
    from stereovo.options import OptionError
    from stereovo.simulation import Sequence, SimulationConfig

    try:
        config = SimulationConfig(
            **{field: getattr(args, flag[2:].replace("-", "_")) for field, flag in _CONFIG_FLAGS.items()}
        )
        sequence = Sequence(config, seed=args.seed)
    except ValueError as err:
        # Invalid settings: the config's OptionError names its field, and the message names the flag.
        field = err.name if isinstance(err, OptionError) and err.rule else None
        raise (UsageError(f"{_CONFIG_FLAGS[field]}{err.rule}") if field in _CONFIG_FLAGS else UsageError(str(err))) \
            from None
    sampling = _sampling(args, args.noise)
    start = RunStart(args.out)
    out: Path = check_output_dir(args.out)  # before computing: a bad --out loses no result
    try:
        result = run_odometry(sequence, method=args.method, seed=args.seed, progress=not args.no_progress, **sampling)
    except ValueError:  # settings the simulator cannot draw a frame from: leave --out as it was
        start.undo()
        raise
    settings = {
        "preset": args.preset, "frames": args.frames, "outliers": args.outliers,
        "outlier_preset": args.outlier_preset, "noise_px": args.noise,
        "n_correspondences": args.n, "score_auc": args.auc, "method": args.method, "seed": args.seed,
        "agent": args.agent,
    }
    agent = "" if args.agent is None else f", sampler {args.agent}"
    _write_result(out, result, settings,
                  f"vo-gym vo: {args.preset}, {args.frames} frames, outliers {args.outliers} ({args.outlier_preset}), "
                  f"noise {args.noise} px, "
                  f"N {args.n}, AUC {args.auc}, seed {args.seed}{agent}")
    return 0


def _write_result(out: Path, result: Any, settings: dict[str, Any], header: str) -> None:
    """Write an :class:`stereovo.odometry.OdometryResult` (trajectories, frames, covariances, plot,
    summary) under ``out`` and print the summary table."""
    import numpy as np

    from stereovo.io import write_frame_csv, write_kitti, write_tum
    from stereovo.plotting import plot_odometry

    write_tum(out / "trajectory_est.tum", result.poses)
    write_tum(out / "trajectory_true.tum", result.true_poses)
    write_kitti(out / "trajectory_est.kitti.txt", result.poses)
    write_kitti(out / "trajectory_true.kitti.txt", result.true_poses)
    write_frame_csv(out / "frames.csv", result.rows())
    np.save(out / "covariances.npy", result.covariances)
    plot_odometry(result, out / "odometry.png")

    summary = result.summary()
    (out / "summary.json").write_text(
        json.dumps(_json_safe({"settings": settings, "metrics": summary}), indent=2) + "\n"
    )
    print(header)
    print("\n".join(_summary_lines(summary)))
    print(f"  wrote {out}/: trajectory_{{est,true}}.tum, trajectory_{{est,true}}.kitti.txt, "
          "frames.csv, covariances.npy, odometry.png, summary.json")


def _write_trajectory(out: Path, estimate: Any, settings: dict[str, Any], header: str) -> None:
    """Write a :class:`stereovo.sequences.sources.TrajectoryEstimate` (no ground truth): the
    estimated trajectory, each frame's outcome, a top-down plot and the summary."""
    import numpy as np
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from stereovo.io import write_frame_csv, write_kitti, write_tum
    from stereovo.plotting import plot_trajectories

    write_tum(out / "trajectory_est.tum", estimate.poses)
    write_kitti(out / "trajectory_est.kitti.txt", estimate.poses)
    write_frame_csv(out / "frames.csv", [
        {"frame": k + 1, "success": bool(ok), "n_matches": int(m), "n_inliers": int(i), "fallback": not bool(ok)}
        for k, (ok, m, i) in enumerate(zip(estimate.ok, estimate.n_matches, estimate.n_inliers))])
    fig = Figure(figsize=(6, 6))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    poses = np.asarray(estimate.poses)
    plot_trajectories(ax, poses, None, label=f"estimate ({estimate.method})")
    ax.set_title("estimated trajectory (no ground-truth poses: no drift)")
    fig.savefig(out / "odometry.png", dpi=110)
    steps = np.linalg.norm(np.diff(poses[:, :3, 3], axis=0), axis=1)
    metrics = {"method": estimate.method, "frames": int(len(estimate.ok)),
               "failed_frames": int(np.count_nonzero(~estimate.ok)),
               "success_rate": float(np.mean(estimate.ok)) if len(estimate.ok) else float("nan"),
               "median_matches": float(np.median(estimate.n_matches)) if len(estimate.ok) else float("nan"),
               "median_inliers": float(np.median(estimate.n_inliers)) if len(estimate.ok) else float("nan"),
               "path_length_m": float(steps.sum()), "kitti_t_percent": None}
    (out / "summary.json").write_text(
        json.dumps(_json_safe({"settings": settings, "metrics": metrics}), indent=2) + "\n")
    print(header)
    print(f"  frames {metrics['frames']} ({metrics['failed_frames']} failed: previous motion reused), "
          f"median {metrics['median_matches']:.0f} matches / {metrics['median_inliers']:.0f} inliers, "
          f"path {metrics['path_length_m']:.1f} m; no ground-truth poses, so no drift")
    print(f"  wrote {out}/: trajectory_est.tum, trajectory_est.kitti.txt, frames.csv, odometry.png, summary.json")


def _read_errors() -> tuple[type[BaseException], ...]:
    """What reading a source's images may raise on a bad file: the loaders' ValueError and OSError, and,
    should one reach here, OpenCV's own error and a failed allocation (an image too large to decode)."""
    import cv2

    return ValueError, OSError, MemoryError, cv2.error


def _source_error(args: argparse.Namespace, err: BaseException) -> UsageError:
    """``--source SOURCE: REASON`` on one line."""
    reason = " ".join(str(err).split()) or type(err).__name__
    return UsageError(f"--source {args.source}: {reason}")


def _open_source(args: argparse.Namespace) -> Any:
    """The image sequence ``--source`` names, its extras checked first; errors name ``--source``."""
    from stereovo.sequences.sources import open_source, parse_source as parse

    kind, named = parse(args.source)
    require_extra("images", "cv2", "PIL", context=f"--source {args.source}")
    if kind == "rendered":
        require_extra("render", "moderngl", "glcontext", context=f"--source {args.source}")
    from stereovo.sequences.rendering import RenderingUnavailable

    frontend = {} if args.detector is None else {"detector": args.detector}
    try:
        if kind == "rendered":
            return open_source(args.source, **({} if "preset" in named else {"preset": args.preset}),
                               n_frames=args.frames, seed=args.seed, resolution=args.resolution,
                               noise_sigma=args.noise, **frontend)
        sequence = open_source(args.source, noise_sigma=args.noise, **frontend)
        if sequence.n_images() > args.frames + 1:  # the first --frames pairs
            sequence = open_source(args.source, noise_sigma=args.noise, stop=args.frames + 1, **frontend)
        return sequence
    except (*_read_errors(), RenderingUnavailable) as err:
        raise _source_error(args, err) from None


def _run_source(args: argparse.Namespace) -> int:
    from stereovo.sequences.sources import run_image_odometry

    sequence = _open_source(args)
    start = RunStart(args.out)
    try:
        sampling = _sampling(args, args.noise)
        out: Path = check_output_dir(args.out)
        try:
            result = run_image_odometry(sequence, method=args.method, seed=args.seed,
                                        progress=not args.no_progress, **sampling)
        except _read_errors() as err:
            # a file read as the sequence goes on (only its first image pair is read when it opens): an
            # unreadable or mis-sized image; --out is left as it was
            start.undo()
            raise _source_error(args, err) from None
        except BaseException:  # anything else (a bug, Ctrl-C) before a result is written: --out as it was
            start.undo()
            raise
    finally:
        close = getattr(sequence, "close", None)
        if close is not None:
            close()
    settings = {"source": args.source, "frames": len(result.poses) - 1, "noise_px": args.noise,
                "method": args.method, "seed": args.seed, "agent": args.agent,
                "detector": sequence.frontend_options.detector}
    if args.source.startswith("rendered"):
        settings["resolution"] = args.resolution
    agent = "" if args.agent is None else f", sampler {args.agent}"
    header = (f"vo-gym vo: {args.source}, {len(result.poses) - 1} frames, noise {args.noise} px, "
              f"seed {args.seed}{agent}")
    if hasattr(result, "true_poses"):
        _write_result(out, result, settings, header)
    else:
        _write_trajectory(out, result, settings, header)
    return 0
