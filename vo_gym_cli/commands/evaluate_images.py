"""``vo-gym evaluate --source rendered[:PRESET]``: the agents on rendered images, success against the budget.

Each episode's frames are rendered once (``--seed + episode``) and matched by the image front end,
then replayed to every agent at every budget through ``vo_gym/StereoVOImages-v0`` (``source=`` those
frames, guided sampling), so every agent sees identical frames. Contamination is the front end's,
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

from vo_gym_cli.commands.common import UsageError, check_output_dir, render_pairs, require_extra


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


def run_on_images(args: argparse.Namespace, default_agents: tuple[str, ...]) -> int:
    """The ``--source`` branch of ``vo-gym evaluate`` (see the module doc); ``default_agents`` when
    no ``--agent`` is given."""
    import gymnasium as gym
    import numpy as np

    import vo_gym  # noqa: F401  (registers the ids)
    from agents.evaluation.setup import resolve_agents
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
    budgets = sorted(set(args.budgets))
    if any(b < 1 for b in budgets):
        raise UsageError(f"--budgets must be integers >= 1, got {args.budgets}")
    out: Path = check_output_dir(args.out)
    if any(a.kind == "checkpoint" for a in agents):
        import torch

        torch.set_num_threads(1)
    progress = not args.no_progress
    episodes = _render(args, preset, progress)
    print(f"vo-gym evaluate: {len(agents)} agent(s) ({', '.join(a.label for a in agents)}) on {args.source} images "
          f"({args.resolution}); {args.episodes} episodes x {args.frames_per_episode} frames; budgets "
          f"{','.join(map(str, budgets))}; seed {args.seed}", flush=True)
    rows: list[dict[str, Any]] = []
    units = [(a, b) for b in budgets for a in agents]
    if progress:
        from tqdm.auto import tqdm

        units = tqdm(units, desc="evaluating", unit="agent x budget")
    for agent, budget in units:
        for e, frames in enumerate(episodes):
            env = gym.make("vo_gym/StereoVOImages-v0", source=frames, n_frames=args.frames_per_episode,
                           sampling="guided",
                           budget=budget)
            policy = agent.build(env)
            obs, _ = env.reset(seed=args.seed + e)
            done, k = False, 0
            while not done:
                action = np.clip(np.asarray(policy.act(obs), dtype=np.float32), -10, 10)
                obs, _, terminated, truncated, info = env.step(action)
                k += 1
                rows.append({"agent": agent.label, "budget": budget, "episode": e, "frame": k,
                             "success": bool(info["success"]), "n_hypotheses": int(info["n_hypotheses"])})
                done = terminated or truncated
            env.close()
    summary = []
    for agent in agents:
        for budget in budgets:
            own = [r for r in rows if r["agent"] == agent.label and r["budget"] == budget]
            hits = sum(r["success"] for r in own)
            low, high = wilson_interval(hits, len(own))
            summary.append({"agent": agent.label, "budget": budget, "frames": len(own), "success": hits / len(own),
                            "ci_low": float(low), "ci_high": float(high),
                            "mean_hypotheses": float(np.mean([r["n_hypotheses"] for r in own]))})
    _write(out, args, rows, summary, budgets, [a.label for a in agents])
    return 0


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
