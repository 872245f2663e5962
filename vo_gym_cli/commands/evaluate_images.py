"""``vo-gym evaluate --source rendered[:PRESET]``: the agents on rendered images, success against the budget.

Each episode's frames are rendered once (``--seed + episode``) and matched by the image front end,
then replayed to every agent at every budget through ``vo_gym/StereoVOImages-v0`` (``source=`` those
frames, guided sampling), so every agent sees identical frames. In-frame samplers run on those frames
through :class:`agents.LearnedEstimator` (batch after batch up to the budget), and the classical
``--methods`` (default ransac, msac, prosac, guided) at the same fixed budget with the environments'
recipe (``"<method> (fixed)"`` rows, as in the simulated evaluation). Contamination is the front end's,
not a chosen one, so there is no contamination sweep. Success is the environment's (within 1 deg /
5 cm of the truth), with Wilson 95 % intervals over the frames.

Writes to ``--out``: ``frames.csv`` (agent, budget, episode, frame, success, hypotheses),
``summary.json``, ``summary.md`` (the table printed here) and ``success_vs_budget.png``.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from vo_gym_cli.commands.common import RunStart, UsageError, open_run_folder, render_pairs, require_extra


def _render(args: argparse.Namespace, preset: str, progress: bool) -> list:
    from vo_gym.images_env import ReplayedFrames

    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=args.episodes * (args.frames_per_episode + 1), desc="rendering + matching", unit="frame")
    episodes = []
    try:
        for i in range(args.episodes):
            # one pair more than an episode: the environment draws the episode's start from its seed
            frames, seq = render_pairs(args.source, preset, args.frames_per_episode + 1, args.seed + i,
                                       args.resolution, advance=None if bar is None else bar.update)
            episodes.append(ReplayedFrames(frames, seq.camera, seq.true_poses, seq.noise_sigma))
    finally:
        if bar is not None:
            bar.close()
    return episodes


def run_on_images(args: argparse.Namespace, default_agents: tuple[str, ...], methods: tuple[str, ...]) -> int:
    """The ``--source`` branch of ``vo-gym evaluate`` (see the module doc); ``default_agents`` when
    no ``--agent`` is given, ``methods`` the classical methods (aliases allowed; none for none).

    ``--out`` is refused when not empty unless ``--overwrite``: the run keeps no journal, so the
    caller refuses ``--resume`` (:func:`vo_gym_cli.commands.evaluate.check_options_apply`)."""
    import gymnasium as gym
    import numpy as np

    import vo_gym  # noqa: F401  (registers the ids)
    from agents.evaluation.run import episode_frames
    from agents.evaluation.setup import IN_FRAME_KIND, normalize_methods, resolve_agents
    from stereovo.reporting import wilson_interval
    from stereovo.sequences.sources import parse_source

    try:
        kind, named = parse_source(args.source)
    except ValueError as err:
        raise UsageError(f"--{err}") from None
    if kind != "rendered":
        raise UsageError(f"--source {args.source!r}: evaluate runs on rendered images (rendered or rendered:PRESET)")
    preset = named.get("preset", "car")
    if preset not in ("car", "free"):
        raise UsageError(f"--source {args.source!r}: the rendered preset must be one of car, free, got {preset!r}")
    require_extra("images", "cv2", context=f"--source {args.source}")
    require_extra("render", "moderngl", "glcontext", context=f"--source {args.source}")
    try:
        agents = resolve_agents(args.agent or default_agents)
    except (ValueError, FileNotFoundError) as err:
        raise UsageError(f"--agent: {err}") from None
    try:
        methods = normalize_methods(methods)
    except ValueError as err:
        raise UsageError(f"--methods: {err}") from None
    budgets = sorted(set(args.budgets))
    if any(b < 1 for b in budgets):
        raise UsageError(f"--budgets must be integers >= 1, got {args.budgets}")
    args.resolution = args.resolution or "kitti"
    start = RunStart(args.out)
    out: Path = open_run_folder(args, resumable=False)  # before any rendering
    if any(a.kind in ("checkpoint", IN_FRAME_KIND) for a in agents):
        import torch

        torch.set_num_threads(1)
    progress = not args.no_progress
    try:
        episodes = _render(args, preset, progress)
    except UsageError:  # the machine cannot render: leave --out as it was
        start.undo()
        raise
    if not args.json:  # --json: the JSON document alone on stdout
        print(f"vo-gym evaluate: {len(agents)} agent(s) ({', '.join(a.label for a in agents)}) and "
              f"{len(methods)} classical method(s) ({', '.join(methods) or 'none'}) on {args.source} images "
              f"({args.resolution}); {args.episodes} episodes x {args.frames_per_episode} frames; budgets "
              f"{','.join(map(str, budgets))}; seed {args.seed}", flush=True)
    rows: list[dict[str, Any]] = []
    units = [(a, b) for b in budgets for a in agents] + [(m, b) for b in budgets for m in methods]
    if progress:
        from tqdm.auto import tqdm

        units = tqdm(units, desc="evaluating", unit="row x budget")
    played = []  # each episode's frames as the environment serves them from its seed
    for e, frames in enumerate(episodes):
        env = gym.make("vo_gym/StereoVOImages-v0", source=frames, n_frames=args.frames_per_episode)
        try:
            played.append(episode_frames(env, args.seed + e))
        finally:
            env.close()
    for who, budget in units:
        for e, frames in enumerate(episodes):
            if isinstance(who, str):
                outcomes = _classical(who, budget, played[e], args.seed + e)
                label = f"{who} (fixed)"
            elif who.kind == IN_FRAME_KIND:
                outcomes = _in_frame(who, budget, played[e], args.seed + e)
                label = who.label
            else:
                outcomes = _through_env(who, budget, frames, args.frames_per_episode, args.seed + e)
                label = who.label
            rows += [{"agent": label, "budget": budget, "episode": e, "frame": k, "success": bool(ok),
                      "n_hypotheses": int(hyps)} for k, (ok, hyps) in enumerate(outcomes, start=1)]
    labels = [a.label for a in agents] + [f"{m} (fixed)" for m in methods]
    summary = []
    for label in labels:
        for budget in budgets:
            own = [r for r in rows if r["agent"] == label and r["budget"] == budget]
            hits = sum(r["success"] for r in own)
            low, high = wilson_interval(hits, len(own))
            summary.append({"agent": label, "budget": budget, "frames": len(own), "success": hits / len(own),
                            "ci_low": float(low), "ci_high": float(high),
                            "mean_hypotheses": float(np.mean([r["n_hypotheses"] for r in own]))})
    _write(out, args, rows, summary, budgets, labels)
    return 0


def _through_env(agent, budget: int, frames, n_frames: int, seed: int) -> list[tuple[bool, int]]:
    """A one-shot agent or heuristic acting through the environment: ``(success, hypotheses)`` a frame."""
    import gymnasium as gym
    import numpy as np

    env = gym.make("vo_gym/StereoVOImages-v0", source=frames, n_frames=n_frames, sampling="guided", budget=budget)
    try:
        policy = agent.build(env)
        obs, _ = env.reset(seed=seed)
        out, done = [], False
        while not done:
            action = np.clip(np.asarray(policy.act(obs), dtype=np.float32), -10, 10)
            obs, _, terminated, truncated, info = env.step(action)
            out.append((info["success"], info["n_hypotheses"]))
            done = terminated or truncated
        return out
    finally:
        env.close()


def _in_frame(agent, budget: int, frames: list, seed: int) -> list[tuple[bool, int]]:
    """An in-frame sampler through :class:`agents.LearnedEstimator` on the episode's frames, at the
    budget batch after batch (its previous estimate feeding the next frame's features)."""
    from agents.estimator import LearnedEstimator
    from stereovo.metrics import frame_metrics

    estimator = LearnedEstimator(agent.source, budget=budget, seed=seed)
    out = []
    for frame in frames:
        est = estimator.estimate(frame.prev, frame.curr, frame.camera, frame.scores)
        out.append((frame_metrics(est, frame.truth).success, est.n_hypotheses))
    return out


def _classical(method: str, budget: int, frames: list, seed: int) -> list[tuple[bool, int]]:
    """A classical method at the budget with the environments' recipe, on the episode's frames."""
    import numpy as np

    from stereovo import benchmark as bm
    from stereovo.metrics import frame_metrics
    from vo_gym.settings import DEFAULT_ESTIMATOR_OPTIONS

    [(_, estimator)] = bm.classical_estimators([method], **DEFAULT_ESTIMATOR_OPTIONS, budget=int(budget),
                                               batch_size=int(budget))
    out = []
    for frame in frames:
        est = estimator(frame, np.random.default_rng([seed, frame.index, budget]))
        out.append((frame_metrics(est, frame.truth).success, est.n_hypotheses))
    return out


def _write(out: Path, args: argparse.Namespace, rows: list[dict], summary: list[dict], budgets: list[int],
           labels: list[str]) -> None:
    import csv

    with (out / "frames.csv").open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    settings = {"source": args.source, "resolution": args.resolution, "episodes": args.episodes,
                "frames_per_episode": args.frames_per_episode, "seed": args.seed, "budgets": budgets,
                "agents": labels, "env_id": "vo_gym/StereoVOImages-v0"}
    (out / "summary.json").write_text(json.dumps({"settings": settings, "rows": summary}, indent=2) + "\n")
    lines = ["| agent | " + " | ".join(f"budget {b}" for b in budgets) + " |",
             "|---|" + "---|" * len(budgets)]
    for label in labels:
        cells = [next(s for s in summary if s["agent"] == label and s["budget"] == b) for b in budgets]
        lines.append(f"| {label} | " + " | ".join(
            f"{100 * c['success']:.1f} % [{100 * c['ci_low']:.1f}, {100 * c['ci_high']:.1f}]" for c in cells) + " |")
    table = ("Success (frames within 1 deg / 5 cm) on rendered images, Wilson 95 % intervals over "
             f"{summary[0]['frames']} frames a cell:\n\n" + "\n".join(lines) + "\n")
    (out / "summary.md").write_text(table)
    written = ["frames.csv", "summary.json", "summary.md"]
    if not args.no_plots:
        from agents.evaluation.report import plot_success_vs_budget

        plot_success_vs_budget(out / f"success_vs_budget.{args.plot_format}", summary, "agent",
                               "rendered images: success vs budget (Wilson 95 % CI)")
        written.append(f"success_vs_budget.{args.plot_format}")
    if args.json:
        print(json.dumps({"settings": settings, "rows": summary}, indent=2))
        return
    print()
    print(table)
    print(f"wrote {out}/: {', '.join(written)}")
