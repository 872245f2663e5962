#!/usr/bin/env python
"""Learned samplers against classical sampling on rendered images: success against the budget,
with Wilson 95 % intervals, and the hypotheses adaptive termination draws.

The frames are rendered once (``car`` drives with moving objects, the ORB front end) and replayed
to every sampler through ``vo_gym/StereoVOImages-v0`` (``source=`` the frames), so each sampler
sees the same frames: its only input is the environment's observation, the one the shipped
samplers were trained on -- with simulated matches. Guided samplers: ``uniform`` (plain MSAC),
the heuristics of ``agents.policies`` (``match-score``: the front end's score; ``consistency``:
rigid consistency), and the shipped learned samplers (``agents.checkpoint.load_sampler``).
``prosac``: the front end's score as PROSAC's order (``vo_gym/StereoVOProsac``-style sampling).

    PYTHONPATH=. python scripts/images_learned_vs_classical.py [--frames 120] [--budgets 1,2,4,8,16] \
        [--json rows.json] [--plot success_vs_budget.png]
    PYTHONPATH=. python scripts/images_learned_vs_classical.py --from-json rows.json --plot out.png  # plot only
"""

from __future__ import annotations

import argparse
import json

import numpy as np

import vo_gym  # noqa: F401


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=120)
    parser.add_argument("--seeds", default="0,1")
    parser.add_argument("--moving-objects", type=int, default=3)
    parser.add_argument("--budgets", default="1,2,4,8,16")
    parser.add_argument("--json", default=None)
    parser.add_argument("--plot", default=None, help="success against budget with the Wilson intervals")
    parser.add_argument("--from-json", default=None, help="plot the rows of an earlier run instead of running")
    args = parser.parse_args()
    if args.from_json:
        with open(args.from_json) as handle:
            plot(json.load(handle), args.plot)
        return
    from tqdm.auto import tqdm

    from agents.checkpoint import SHIPPED_SAMPLERS, load_sampler
    from agents.policies import make_heuristic
    from stereovo.sequences.rendered import RenderedSequence
    from stereovo.reporting import wilson_interval
    from vo_gym.images_env import ReplayedFrames, StereoVOImagesEnv

    sources = []
    for seed in (int(s) for s in args.seeds.split(",")):
        seq = RenderedSequence("car", n_frames=args.frames, seed=seed, moving_objects=args.moving_objects)
        frames = [seq.frame(k) for k in tqdm(range(1, args.frames + 1), desc=f"rendering seed {seed}", unit="frame")]
        inl = np.concatenate([f.truth.inlier for f in frames])
        print(f"seed {seed}: {np.mean([f.n for f in frames]):.0f} matches per frame, labelled inlier rate {inl.mean():.3f}")
        sources.append(ReplayedFrames(frames, seq.camera, seq.true_poses, seq.noise_sigma))
        seq.close()
    policies = {name: make_heuristic(name) for name in ("uniform", "match-score", "consistency")}
    policies.update({name: load_sampler(name) for name in SHIPPED_SAMPLERS})
    budgets = [int(b) for b in args.budgets.split(",")]
    rows = []

    def run(sampling, budget, act, label):
        hits, n, hyp = 0, 0, []
        for source in sources:
            env = StereoVOImagesEnv(source=source, n_frames=len(source) - 1, sampling=sampling, budget=budget)
            obs, _ = env.reset(seed=0)
            done = False
            while not done:
                obs, _, terminated, truncated, info = env.step(act(obs))
                hits += bool(info["success"])
                n += 1
                hyp.append(info["n_hypotheses"])
                done = terminated or truncated
            env.close()
        low, high = (float(x) for x in wilson_interval(hits, n))
        row = dict(sampler=label, budget=budget if budget is not None else "adaptive", frames=n,
                   success=hits / n, ci_low=low, ci_high=high, mean_hypotheses=float(np.mean(hyp)))
        rows.append(row)
        print(f"{label:34s} budget {str(row['budget']):>8s}: success {100 * row['success']:5.1f} % "
              f"[{100 * low:5.1f}, {100 * high:5.1f}], mean hypotheses {row['mean_hypotheses']:.1f}", flush=True)

    from vo_gym.features import feature_index

    score_index = feature_index("match_score")
    for budget in budgets + [None]:
        for name, policy in policies.items():
            run("guided", budget, lambda obs, p=policy: np.clip(p.act(obs), -10, 10), name)
        run("prosac", budget, lambda obs: obs["features"][:, score_index] * obs["mask"], "prosac (front-end score order)")
    if args.json:
        with open(args.json, "w") as handle:
            json.dump(rows, handle, indent=1)
    if args.plot:
        plot(rows, args.plot)


def plot(rows: list[dict], path: str | None) -> None:
    """Success (%) against the fixed budgets, one line per sampler, Wilson 95 % intervals as bars."""
    if path:
        from agents.evaluation.report import plot_success_vs_budget

        plot_success_vs_budget(path, rows, "sampler",
                               "rendered car drives with moving cars: success vs budget (95 % Wilson CI)")


if __name__ == "__main__":
    main()
