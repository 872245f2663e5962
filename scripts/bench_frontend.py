"""Speed of the image front end and the renderer against the issue's targets, in one run.

- Front end: detect (both images of the new pair) + stereo + temporal per frame pair, streaming
  (each pair is detected once), at 1241x376 with 2000 ORB features, on one core (OpenCV and
  numba single-threaded). Target <= 15 ms. Also the stateless ``match_stereo_frames`` (four
  detections) and each stage apart.
- Rendering: one stereo pair (left with depth and ids, right grey) at 1241x376 and 640x480.
  Target <= 20 ms. llvmpipe's threads follow ``LP_NUM_THREADS`` (default: all cores).

Kernels are compiled and every stage warmed up before timing; medians over ``--repeats`` frames.

    PYTHONPATH=. python scripts/bench_frontend.py [--frames 30]
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np


def _median_ms(samples: list[float]) -> float:
    return 1e3 * float(np.median(samples))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=30)
    args = parser.parse_args()
    import cv2
    import numba

    cv2.setNumThreads(1)
    numba.set_num_threads(1)
    from stereovo.frontend import StereoFrontend, match_stereo_frames
    from stereovo.frontend.detection import detect
    from stereovo.frontend.stereo import match_pair
    from stereovo.sequences.rendered import RenderedSequence

    print(f"OpenCV {cv2.__version__}, {os.cpu_count()} cores visible, LP_NUM_THREADS={os.environ.get('LP_NUM_THREADS', 'unset')}")
    for resolution in ("kitti", "vga"):
        seq = RenderedSequence("car", n_frames=args.frames + 2, resolution=resolution, seed=0, texture_seed=0)
        seq.images(0)  # warm the renderer
        render = []
        for k in range(1, args.frames + 1):
            start = time.perf_counter()
            seq.images(k)
            render.append(time.perf_counter() - start)
        cam = seq.camera
        print(f"rendering {cam.width}x{cam.height}: {_median_ms(render):.1f} ms per stereo pair "
              f"(target 20 ms: {'met' if _median_ms(render) <= 20 else 'NOT met'}, ratio {_median_ms(render) / 20:.2f})")
        if resolution != "kitti":
            continue
        pairs = [seq.images(k) for k in range(args.frames + 1)]
        frontend = StereoFrontend(cam)
        opts = frontend.options
        frontend.push(*pairs[0])
        frontend.push(*pairs[1])  # compiled and warm
        frontend.reset()
        frontend.push(*pairs[0])
        stream, det, stereo, temporal, stateless = [], [], [], [], []
        prev = frontend.features(*pairs[0])
        for left, right in pairs[1:]:
            start = time.perf_counter()
            frontend.push(left, right)
            stream.append(time.perf_counter() - start)
            t0 = time.perf_counter()
            kl, kr = detect(left, opts), detect(right, opts)
            t1 = time.perf_counter()
            curr = match_pair(left, right, kl, kr, cam, opts)
            t2 = time.perf_counter()
            frontend.match(prev, curr)
            t3 = time.perf_counter()
            det.append(t1 - t0)
            stereo.append(t2 - t1)
            temporal.append(t3 - t2)
            prev = curr
        for (l0, r0), (l1, r1) in zip(pairs[:5], pairs[1:6]):
            start = time.perf_counter()
            match_stereo_frames(l0, r0, l1, r1, cam)
            stateless.append(time.perf_counter() - start)
        total = _median_ms(stream)
        print(f"front end 1241x376, {opts.n_features} ORB features, one core: {total:.1f} ms per frame pair "
              f"streaming (target 15 ms: {'met' if total <= 15 else 'NOT met'}, ratio {total / 15:.2f}); "
              f"detect both images {_median_ms(det):.1f} ms, stereo {_median_ms(stereo):.2f} ms, "
              f"temporal {_median_ms(temporal):.2f} ms; stateless match_stereo_frames (4 detections) "
              f"{_median_ms(stateless):.1f} ms")
        seq.close()


if __name__ == "__main__":
    main()
