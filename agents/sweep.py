"""Training sweeps on Ray Tune: the NG-RANSAC and PPO trainers as Tune function trainables, and the sweep's outputs.

The sweep file and its checks are :mod:`agents.sweep_config`'s (:func:`~agents.sweep_config.load_sweep`
gives the :class:`~agents.sweep_config.SweepSpec` that :func:`run_sweep` runs).

Every report carries a checkpoint (the trainer's own format), so a trial resumes where it was and
the best trial's weights are kept. Results, the metric over training and the best config are
written by :func:`write_sweep_outputs`.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import tempfile
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Mapping

from agents.sweep_config import METRIC, MetricSpec, SweepSpec

__all__ = [
    "held_out_success",
    "sweep_trainable",
    "run_sweep",
    "SweepOutcome",
    "write_sweep_outputs",
]


def param_space(spec: SweepSpec) -> dict[str, Any]:
    """Tune's search space for the spec's axes."""
    from ray import tune

    out: dict[str, Any] = {}
    for key, axis in spec.space.items():
        [(kind, values)] = axis.items()
        if kind == "grid":
            out[key] = tune.grid_search(list(values))
        elif kind == "choice":
            out[key] = tune.choice(list(values))
        elif kind == "uniform":
            out[key] = tune.uniform(*values)
        elif kind == "loguniform":
            out[key] = tune.loguniform(*values)
        else:
            out[key] = tune.randint(int(values[0]), int(values[1]))
    return out


# --------------------------------------------------------------------------- trainable


def held_out_success(net, metric: MetricSpec) -> float:
    """The sweep metric: frame success rate of ``net`` acting in the environment (see :class:`MetricSpec`)."""
    from agents.checkpoint import LearnedPolicy
    from agents.rollout import success_rate

    was_training = net.training
    try:
        success, _ = success_rate(LearnedPolicy(net, "sweep"), metric.env_id, metric.env_kwargs(), metric.seeds())
    finally:
        net.train(was_training)
    return float(success)


def _report(metrics: dict[str, Any], save: Any) -> None:
    from ray import tune

    with tempfile.TemporaryDirectory() as folder:
        save(Path(folder))
        tune.report(metrics, checkpoint=tune.Checkpoint.from_directory(folder))


def _train_ngransac(spec: SweepSpec, params: Mapping[str, Any]) -> None:
    from ray import tune

    from agents.ngransac import NGRansacTrainer

    config = spec.trainer_config(params)
    checkpoint = tune.get_checkpoint()
    if checkpoint is not None:
        with checkpoint.as_directory() as folder:
            trainer = NGRansacTrainer.resume(Path(folder) / "ngransac.pt")
    else:
        trainer = NGRansacTrainer(config)
    while trainer.step < config.frames:
        trainer.train(frames=min(spec.report_every, config.frames - trainer.step))
        success = held_out_success(trainer.net, spec.metric)
        last = trainer.history[-1] if trainer.history else None
        metrics = {METRIC: success, "step": trainer.step,
                   "train_loss": float(last.mean_loss) if last is not None else float("nan")}
        _report(metrics, lambda folder: trainer.save(folder / "ngransac.pt"))


def _train_ppo(spec: SweepSpec, params: Mapping[str, Any]) -> None:
    from ray import tune

    from agents.ppo.archive import load_ppo
    from agents.ppo.config import build_model, make_training_env
    from agents.ppo.train import export_actor

    config = spec.trainer_config(params)
    env = make_training_env(config)
    try:
        checkpoint = tune.get_checkpoint()
        if checkpoint is not None:
            with checkpoint.as_directory() as folder:
                model = load_ppo(Path(folder) / "ppo.zip", env=env)
        else:
            model = build_model(config, env)
        while model.num_timesteps < config.timesteps:
            step = min(spec.report_every, config.timesteps - model.num_timesteps)
            model.learn(total_timesteps=step, reset_num_timesteps=False, progress_bar=False)
            success = held_out_success(model.policy.action_net, spec.metric)

            def save(folder: Path) -> None:
                model.save(str(folder / "ppo.zip"))
                export_actor(model, folder / "ppo.pt", config)

            _report({METRIC: success, "step": int(model.num_timesteps)}, save)
    finally:
        env.close()


def sweep_trainable(params: dict[str, Any], spec: dict[str, Any]) -> None:
    """Tune function trainable: one trainer config (``spec.fixed`` + ``params``), reported every ``report_every``."""
    import torch

    # One intra-op thread per trial: Tune runs trials side by side, one CPU each.
    torch.set_num_threads(1)
    sweep = SweepSpec(**{**spec, "metric": MetricSpec(**spec["metric"])})
    if sweep.algo == "ngransac":
        _train_ngransac(sweep, params)
    else:
        _train_ppo(sweep, params)


# --------------------------------------------------------------------------- running


@dataclass
class SweepOutcome:
    """What a sweep left: every trial's history, and whether every trial finished."""

    trials: list[dict[str, Any]]
    complete: bool
    experiment: Path
    errors: int = 0


def trial_bar(total: int):
    """A Tune callback that shows the sweep as one tqdm bar over its trials (Tune's own table is off)."""
    from ray.tune import Callback
    from tqdm.auto import tqdm

    class TrialBar(Callback):
        def __init__(self) -> None:
            self.bar = None

        def setup(self, total_num_samples=None, **info):
            self.bar = tqdm(total=total_num_samples or total, desc="sweep", unit="trial", dynamic_ncols=True)

        def on_trial_complete(self, iteration, trials, trial, **info):
            self.bar.update(1)

        on_trial_error = on_trial_complete

        def on_experiment_end(self, trials, **info):
            self.bar.close()

    return TrialBar()


def run_sweep(spec: SweepSpec, out: str | os.PathLike, workers: int | None = None, address: str | None = None,
              resume: bool = False, verbose: int = 0, progress: bool = True) -> SweepOutcome:
    """Run (or with ``resume`` restore and complete) the sweep in ``out/tune``.

    Without ``address`` a local Ray instance with ``workers`` CPUs is started (and shut down);
    ``address="auto"`` or ``"HOST:PORT"`` joins a cluster. Trials run side by side, one CPU each.
    A Ctrl-C makes Tune save the experiment; ``resume`` continues it from the last checkpoints.
    """
    import ray
    from ray import tune
    from ray.tune.schedulers import ASHAScheduler, FIFOScheduler
    from ray.tune.search.basic_variant import BasicVariantGenerator

    from stereovo.trials.backend import connect_ray

    out = Path(out).resolve()
    experiment = out / "tune"
    if not verbose:
        # Tune's newer console output prints its heading and result paths even at verbose 0; the
        # classic reporter is silent there.
        os.environ.setdefault("RAY_AIR_NEW_OUTPUT", "0")
    started = connect_ray(workers, address, log_to_driver=verbose > 0)
    try:
        trainable = tune.with_resources(tune.with_parameters(sweep_trainable, spec=spec.as_dict()), {"cpu": 1})
        if resume and tune.Tuner.can_restore(str(experiment)):
            tuner = tune.Tuner.restore(str(experiment), trainable, resume_unfinished=True, resume_errored=True)
        else:
            if spec.scheduler["type"] == "asha":
                scheduler = ASHAScheduler(time_attr="training_iteration", max_t=spec.n_reports,
                                          grace_period=min(spec.scheduler["grace_period"], spec.n_reports),
                                          reduction_factor=spec.scheduler["reduction_factor"])
            else:
                scheduler = FIFOScheduler()
            tuner = tune.Tuner(
                trainable, param_space=param_space(spec),
                tune_config=tune.TuneConfig(metric=METRIC, mode="max", scheduler=scheduler, num_samples=spec.samples,
                                            max_concurrent_trials=workers,
                                            search_alg=BasicVariantGenerator(random_state=spec.search_seed)),
                run_config=tune.RunConfig(name="tune", storage_path=str(out), verbose=verbose,
                                          checkpoint_config=tune.CheckpointConfig(num_to_keep=None),
                                          callbacks=[trial_bar(spec.samples)] if progress and not verbose else None),
            )
        grid = tuner.fit()
        trials, errors = [], 0
        for result in grid:
            frame = result.metrics_dataframe
            history = [] if frame is None or METRIC not in frame else [
                {"step": int(s), METRIC: float(v)} for s, v in zip(frame["step"], frame[METRIC])]
            best = None
            if result.best_checkpoints:
                best = max(result.best_checkpoints, key=lambda cm: cm[1].get(METRIC, -1.0))
            trials.append({
                "trial": str((result.metrics or {}).get("trial_id") or (Path(result.path).name if result.path else "?")),
                "params": dict(result.config or {}),
                "history": history,
                "error": None if result.error is None else " ".join(str(result.error).split())[:300],
                "best_checkpoint": None if best is None else best[0].path,
                "best_success": None if best is None else float(best[1].get(METRIC)),
            })
            errors += result.error is not None
        complete = _experiment_complete(experiment)
        return SweepOutcome(trials, complete, experiment, errors)
    finally:
        if started:
            ray.shutdown()


def _experiment_complete(experiment: Path) -> bool:
    """Whether Tune's saved experiment has every trial TERMINATED (finished, or stopped by ASHA) or ERROR.

    Read from the saved state, not from ``fit()``'s answer: after a Ctrl-C, ``fit()`` returns
    normally with trials that are still PENDING or RUNNING in the saved state.
    """
    from ray.tune import ExperimentAnalysis

    try:
        trials = ExperimentAnalysis(str(experiment)).trials
    except Exception:  # noqa: BLE001 - no readable state: not complete
        return False
    return bool(trials) and all(t.status in ("TERMINATED", "ERROR") for t in trials)


def write_sweep_outputs(spec: SweepSpec, outcome: SweepOutcome, out: str | os.PathLike) -> list[Path]:
    """``results.csv`` / ``results.md`` (a row per trial), ``metric_over_training.png``, ``best.json``
    (the best trial's config and metric) and ``best_checkpoint/`` (its checkpoint files)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from stereovo.benchmark import markdown_table
    from stereovo.io import write_frame_csv
    from stereovo.trials.store import atomic_path, atomic_write_text

    out = Path(out)
    keys = list(spec.space)
    rows = []
    for t in outcome.trials:
        hist = t["history"]
        rows.append({
            "trial": t["trial"], **{k: t["params"].get(k) for k in keys},
            "reports": len(hist), "steps": hist[-1]["step"] if hist else 0,
            "last_success": hist[-1][METRIC] if hist else math.nan,
            "best_success": max((h[METRIC] for h in hist), default=math.nan),
            "status": "error" if t["error"] else ("not started" if not hist else
                                                  "finished" if hist[-1]["step"] >= spec.total_steps
                                                  else "stopped early"),
        })
    rows.sort(key=lambda r: (-(r["best_success"] if r["best_success"] == r["best_success"] else -1), r["trial"]))
    with atomic_path(out / "results.csv") as tmp:
        write_frame_csv(tmp, rows)
    paths = [out / "results.csv"]

    def fmt(v: Any) -> str:
        return f"{v:.3g}" if isinstance(v, float) else str(v)

    table = markdown_table(["trial", *keys, "reports", "steps", "last success", "best success", "status"],
                           [[r["trial"], *(fmt(r[k]) for k in keys), r["reports"], r["steps"], fmt(r["last_success"]),
                             fmt(r["best_success"]), r["status"]] for r in rows])
    unit = "frames" if spec.algo == "ngransac" else "environment steps"
    text = [f"# Sweep {spec.name} ({spec.algo})", "",
            f"Metric: {spec.metric.describe()}; reported every {spec.report_every} {unit} of {spec.total_steps};"
            f" scheduler {spec.scheduler['type']}; {len(rows)} trials.", "", table, ""]
    candidates = [t for t in outcome.trials if t["best_checkpoint"]]
    best = max(candidates, key=lambda t: t["best_success"], default=None)
    if best is not None:
        target = out / "best_checkpoint"
        if target.exists():
            shutil.rmtree(target)
        shutil.copytree(best["best_checkpoint"], target)
        payload = {"trial": best["trial"], "params": best["params"], METRIC: best["best_success"],
                   "metric": spec.metric.describe(),
                   "config": {k: (list(v) if isinstance(v, tuple) else v)
                              for k, v in asdict(spec.trainer_config(best["params"])).items()},
                   "checkpoint": str(target)}
        atomic_write_text(out / "best.json", json.dumps(payload, indent=2, default=str) + "\n")
        text += [f"Best: trial {best['trial']}, {METRIC} {best['best_success']:.3f} with"
                 f" {json.dumps(best['params'], default=str)}; checkpoint in `best_checkpoint/`.", ""]
        paths += [out / "best.json", target]
    atomic_write_text(out / "results.md", "\n".join(text))
    paths.append(out / "results.md")

    fig = Figure(figsize=(9, 5.2), layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    for t in outcome.trials:
        if t["history"]:
            xs = [h["step"] for h in t["history"]]
            ys = [100 * h[METRIC] for h in t["history"]]
            label = ", ".join(f"{k}={fmt(t['params'].get(k))}" for k in keys)
            ax.plot(xs, ys, marker="o", ms=3, lw=1.2, label=label)
    ax.set_xlabel(f"training {unit}")
    ax.set_ylabel("held-out success [%]")
    ax.set_ylim(-2, 102)
    ax.set_title(f"{spec.name}: {spec.metric.describe()}", fontsize="small")
    ax.grid(True, alpha=0.3)
    if any(t["history"] for t in outcome.trials):
        ax.legend(loc="center left", bbox_to_anchor=(1.01, 0.5), fontsize="x-small")
    fig.savefig(out / "metric_over_training.png", dpi=110)
    paths.append(out / "metric_over_training.png")
    return paths
