"""How the baseline grid scales with the backend: the local pool at 1 and 2 workers, Ray at 1 and 2.

    .venv/bin/python scripts/bench_scaling.py                      # the default grid, every method
    .venv/bin/python scripts/bench_scaling.py --frames-per-cell 3  # a quicker look

Every configuration runs the same trials (same seed: the rows are identical, checked here). Its
start-up (Ray's instance, and every worker's one warm-up: numba loading its cache) is timed apart:
a long run pays it once. Printed:

- the wall time of each configuration and its speed-up against one local worker;
- Ray's overhead per task in ms, two ways: on empty tasks (Ray with one CPU against a plain loop)
  and on the grid itself ((Ray 1 worker - local 1 worker) / tasks), against the median trial;
- whether the targets hold: Ray at 2 workers >= 1.7x one local worker, overhead <= 5 % of the
  median trial;
- what M machines of this kind are expected to give (Amdahl with the measured overhead).

Wall times depend on what else the machine runs: the script prints the load average before and
after so a reader can judge the conditions.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from functools import partial
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from stereovo import benchmark as bm  # noqa: E402
from stereovo.trials import LocalBackend, RayBackend, Task, run_tasks  # noqa: E402


def _noop(x):
    return x


def _empty_task_overhead_ms(n: int) -> float:
    """(Ray with one CPU - a plain loop) per empty task, ms."""
    tasks = [Task(i, i) for i in range(n)]
    start = time.perf_counter()
    run_tasks(_noop, tasks, LocalBackend(1), progress=False)
    local = time.perf_counter() - start
    backend = RayBackend(1)
    try:
        run_tasks(_noop, tasks[:20], backend, progress=False)  # workers up and warm
        start = time.perf_counter()
        run_tasks(_noop, tasks, backend, progress=False)
        ray_s = time.perf_counter() - start
    finally:
        backend.close()
    return 1e3 * (ray_s - local) / n


def _pause(seconds):
    # Holds its worker a moment, so the warm-up tasks land on different workers.
    time.sleep(seconds)
    return seconds


def _timed(kind: str, workers: int, trials, estimators, seed: int, chunk: int) -> tuple[float, float, list]:
    """(start-up s, run wall s, rows) of one configuration.

    Start-up is the backend's (Ray's instance) plus every worker's one warm-up (numba loading its
    cache, first calls), paid once per run however long: timed apart, as a long run amortises it.
    """
    start = time.perf_counter()
    backend = LocalBackend(workers) if kind == "local" else RayBackend(workers)
    try:
        warm = partial(bm.warm_up_estimators, estimators)  # the very warm-up run_benchmark passes
        run_tasks(_pause, [Task(i, 0.5) for i in range(workers)], backend, warmup=warm, progress=False)
        startup = time.perf_counter() - start
        start = time.perf_counter()
        rows = bm.run_benchmark(trials, estimators, seed=seed, progress=False, backend=backend, chunk=chunk)
        wall = time.perf_counter() - start
    finally:
        backend.close()
    return startup, wall, rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames-per-cell", type=int, default=None, help="override the default grid's 10")
    parser.add_argument("--methods", default=None, help="comma-separated methods (default: all)")
    parser.add_argument("--chunk", type=int, default=1, help="frames per task (default 1)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--empty-tasks", type=int, default=500, help="empty tasks for the overhead probe")
    parser.add_argument("--json", type=Path, default=None, help="also write the figures here")
    args = parser.parse_args(argv)

    grid = bm.DEFAULT_GRID.with_axes(frames_per_cell=args.frames_per_cell)
    estimators = bm.classical_estimators(args.methods.split(",") if args.methods else None,
                                         max_iterations=grid.max_iterations)
    trials = grid.trials()
    load_before = os.getloadavg()
    print(f"grid: {grid.describe()}; {len(estimators)} methods; chunk {args.chunk}; {bm.default_workers()} CPUs;"
          f" load average {load_before[0]:.2f} {load_before[1]:.2f} {load_before[2]:.2f}", flush=True)

    # Compile (or load numba's cache) once, untimed: otherwise the first configuration pays the compiling.
    start = time.perf_counter()
    bm.warm_up_estimators(estimators)
    print(f"warm-up (compiling on a first run): {time.perf_counter() - start:.1f} s", flush=True)
    overhead_empty = _empty_task_overhead_ms(args.empty_tasks)
    print(f"Ray overhead on empty tasks: {overhead_empty:.2f} ms per task", flush=True)

    results: dict[str, dict[str, float]] = {}
    reference = None
    for kind, workers in (("local", 1), ("local", 2), ("ray", 1), ("ray", 2)):
        startup, wall, rows = _timed(kind, workers, trials, estimators, args.seed, args.chunk)
        stripped = [{k: v for k, v in r.items() if k not in bm.TIME_COLUMNS} for r in rows]
        if reference is None:
            reference = stripped
            per_trial: dict[int, float] = {}
            for r in rows:
                per_trial[r["trial"]] = per_trial.get(r["trial"], 0.0) + r["time_s"]
            median_trial_ms = 1e3 * statistics.median(per_trial.values())
        same = stripped == reference or all(
            a == b or all((x == y) or (x != x and y != y) for x, y in zip(a.values(), b.values()))
            for a, b in zip(stripped, reference))
        name = f"{kind} x{workers}"
        results[name] = {"startup_s": startup, "wall_s": wall, "same_rows": bool(same)}
        print(f"  {name:<9} wall {wall:7.1f} s   start-up {startup:5.1f} s   rows identical: {same}", flush=True)

    base = results["local x1"]["wall_s"]
    n_tasks = -(-len(trials) // args.chunk)
    overhead_grid = 1e3 * (results["ray x1"]["wall_s"] - base) / n_tasks
    print(f"\nmedian trial (all methods on one frame): {median_trial_ms:.1f} ms; {len(trials)} trials in {n_tasks} tasks")
    print(f"{'config':<9} {'wall [s]':>9} {'speed-up vs local x1':>21}")
    for name, r in results.items():
        r["speedup"] = base / r["wall_s"]
        print(f"{name:<9} {r['wall_s']:9.1f} {r['speedup']:20.2f}x")
    share_empty = overhead_empty / median_trial_ms
    share_grid = overhead_grid / median_trial_ms
    print(f"Ray overhead per task: {overhead_empty:.2f} ms on empty tasks ({100 * share_empty:.2f} % of the median"
          f" trial); {overhead_grid:.1f} ms from the grid (ray x1 - local x1, {100 * share_grid:.1f} %; includes"
          " noise from other load)")
    speed_ok = results["ray x2"]["speedup"] >= 1.7
    over_ok = share_empty <= 0.05
    print(f"target ray x2 >= 1.7x local x1: {'met' if speed_ok else 'NOT met'} ({results['ray x2']['speedup']:.2f}x);"
          f" overhead <= 5 % of the median trial: {'met' if over_ok else 'NOT met'} ({100 * share_empty:.2f} %)")
    # Expected throughput on M machines of C cores: each core runs trials of the measured mean cost plus the
    # per-task overhead; the driver's bookkeeping (journal append and fsync, about a ms) is serial.
    mean_trial_s = base / len(trials)
    per_core = 1.0 / (mean_trial_s + overhead_empty / 1e3)
    cores = bm.default_workers()
    print(f"expected trials/s on M machines of {cores} cores (mean trial {1e3 * mean_trial_s:.0f} ms + overhead):")
    for m in (1, 4, 16, 64):
        print(f"  M = {m:>2}: {m * cores * per_core:8.1f} trials/s  ({m * cores * per_core / (1 / mean_trial_s):.1f}x"
              " one local worker)")
    load_after = os.getloadavg()
    print(f"load average after: {load_after[0]:.2f} {load_after[1]:.2f} {load_after[2]:.2f}")
    if args.json is not None:
        args.json.write_text(json.dumps({
            "grid": grid.describe(), "methods": len(estimators), "chunk": args.chunk, "results": results,
            "median_trial_ms": median_trial_ms, "overhead_empty_ms": overhead_empty,
            "overhead_grid_ms": overhead_grid, "load_before": load_before, "load_after": load_after,
        }, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
