"""Visual odometry on rendered images: the issue's accuracy targets, measured.

On a rendered ``car`` sequence (default 500 frames, 1241x376, ORB front end) the default method
(``estimate_motion(..., method="probabilistic")``) must put >= 99 % of the frames within 1 deg /
5 cm (the shared success criterion, :mod:`stereovo.metrics`) and keep KITTI-style translational
drift <= 1 %. Prints both against their targets, the front end's labelled inlier rate and score
ROC AUC, and the estimator's inlier precision and recall.

    PYTHONPATH=. python scripts/bench_image_odometry.py [--frames 500] [--seed 0] [--preset car]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from stereovo.frontend import roc_auc
from stereovo.frontend.options import option_value
from stereovo.sequences import open_source, run_image_odometry


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=500)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--preset", default="car", choices=("car", "free"))
    parser.add_argument("--resolution", default="kitti", choices=("kitti", "vga"))
    parser.add_argument("--moving-objects", type=int, default=0)
    parser.add_argument("--method", default="probabilistic")
    parser.add_argument("--frontend", nargs="*", default=[], metavar="NAME=VALUE",
                        help="front-end options (FrontendOptions fields), e.g. pyramid_levels=4 fast_threshold=12")
    args = parser.parse_args()
    frontend = {}
    for item in args.frontend:
        name, sep, value = item.partition("=")
        if not sep:
            parser.error(f"--frontend takes NAME=VALUE items, got {item!r}")
        frontend[name] = option_value(value)

    sequence = open_source(f"rendered:{args.preset}", n_frames=args.frames, seed=args.seed,
                           resolution=args.resolution, moving_objects=args.moving_objects, **frontend)
    aucs, inlier_rates, counts = [], [], []

    class Recording:
        """The sequence, recording each frame's labelled inlier rate and score AUC on the way."""

        camera, true_poses = sequence.camera, sequence.true_poses

        def __len__(self):
            return len(sequence)

        def __iter__(self):
            for frame in sequence:
                inliers = frame.truth.inlier
                inlier_rates.append(float(inliers.mean()) if inliers.size else 0.0)
                aucs.append(roc_auc(frame.scores, inliers))
                counts.append(frame.n)
                yield frame

    start = time.perf_counter()
    result = run_image_odometry(Recording(), method=args.method, seed=args.seed, progress=True)
    wall = time.perf_counter() - start
    s = result.summary()
    success = result.column("success").astype(bool)
    n = success.size
    # Wilson 95 % interval of the success rate
    z, p = 1.96, success.mean()
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    print(f"{sequence!r}, method {args.method}, {n} frames in {wall:.0f} s ({n / wall:.1f} frames/s, all stages)")
    print(f"matches per frame: median {np.median(counts):.0f} (min {min(counts)}), labelled inlier rate "
          f"median {np.median(inlier_rates):.3f}, score ROC AUC median {np.nanmedian(aucs):.3f} "
          f"(mean {np.nanmean(aucs):.3f})")
    print(f"success (1 deg / 5 cm): {100 * p:.2f} % (95 % CI {100 * (centre - half):.2f}-{100 * (centre + half):.2f}); "
          f"target >= 99 %: {'met' if p >= 0.99 else 'NOT met'}")
    print(f"median rotation error {s['median_rot_err_deg']:.4f} deg, translation {100 * s['median_trans_err_m']:.2f} cm; "
          f"inlier precision {s['mean_precision']:.3f}, recall {s['mean_recall']:.3f}")
    failed = np.flatnonzero(~success)
    for i in failed[:20]:
        m = result.frames[i]
        print(f"  unsuccessful frame {result.frame_indices[i]}: {counts[i]} matches, inlier rate {inlier_rates[i]:.2f}, "
              f"rotation error {m.rot_err_deg:.3f} deg, translation error {100 * m.trans_err_m:.1f} cm, status {m.status}")
    drift = s["kitti_t_percent"]
    print(f"KITTI drift: {drift:.3f} % translation, {100 * s['kitti_r_deg_per_m']:.3f} deg/100 m over "
          f"{s['kitti_segments']} segments, path {s['path_length_m']:.0f} m; target <= 1 %: "
          f"{'met' if drift <= 1.0 else 'NOT met' if np.isfinite(drift) else 'no segment (path < 100 m)'}")


if __name__ == "__main__":
    main()
