"""Estimator options that the estimator would not read with the other settings are refused, not ignored.

Under a fixed ``budget`` (StereoVOEnv's default, 32) no adaptive stop runs; ``least_squares_refit``
chooses the final step only without ``refine`` (the environments' default is ``refine=True``); the
reprojection-judged methods (``msac``, the default) read neither gate quantile. Each such option used
to give a stream bit-identical to the defaults. The last test checks :func:`vo_gym.settings.unread_options`
(the estimator's declarations, with the environment's settings) against the estimator itself: every option
it refuses for a method leaves its estimates unchanged (run with the estimator's own refusal switched off,
since it refuses them too).
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import vo_gym  # noqa: F401  (registers the ids)
from stereovo.estimation import StereoProblem, api, available_methods, drop_unread, estimate_problem, method_spec
from stereovo.simulation import Sequence, SimulationConfig
from vo_gym.adaptive_env import StereoVOAdaptiveEnv
from vo_gym.env import StereoVOEnv
from vo_gym.settings import DEFAULT_ESTIMATOR_OPTIONS

SMALL = dict(n_frames=2, n_correspondences=40)
BUDGET_ONLY = {"confidence": 0.5, "max_iterations": 1, "first_batch_size": 1, "fail_at_cap": False}


def _refusal(env_id_or_cls, **kwargs) -> str:
    with pytest.raises(ValueError) as err:
        if isinstance(env_id_or_cls, str):
            gym.make(env_id_or_cls, **SMALL, **kwargs)
        else:
            env_id_or_cls(**SMALL, **kwargs)
    return str(err.value)


@pytest.mark.parametrize("env_id", ["vo_gym/StereoVO-v0", "vo_gym/StereoVOProsac-v0", "vo_gym/StereoVOHard-v0",
                                    "vo_gym/StereoVOProsacHard-v0"])
@pytest.mark.parametrize("name, value", sorted(BUDGET_ONLY.items()))
def test_the_adaptive_stops_options_are_refused_under_the_default_fixed_budget(env_id, name, value):
    message = _refusal(env_id, **{name: value})
    assert message.startswith(f"StereoVOEnv: {name}={value!r} would be ignored: a fixed budget (budget=32) draws "
                              "exactly that many hypotheses per frame"), message
    assert message.endswith("(budget=None switches to the adaptive stop)"), message
    # the same keyword is read, and accepted, by the adaptive stop
    env = gym.make(env_id, **SMALL, budget=None, **{name: value})
    assert getattr(env.unwrapped.estimator_options, name) == value


def test_a_prosac_stop_keeps_confidence_under_a_budget_and_nothing_else_of_the_adaptive_stop():
    # PROSAC's stop still picks the sampled prefix n* with its confidence under a fixed budget
    for kwargs in ({"method": "prosac"}, {"method": "usac"}):
        env = StereoVOEnv(**SMALL, sampling="prosac", confidence=0.9, **kwargs)
        assert env.estimator_options.confidence == 0.9
        assert "max_iterations=5 would be ignored" in _refusal(StereoVOEnv, sampling="prosac", max_iterations=5, **kwargs)
    # usac without an order builds no PROSAC stop
    assert "confidence=0.9 would be ignored" in _refusal(StereoVOEnv, method="usac", confidence=0.9)


@pytest.mark.parametrize("cls", [StereoVOEnv, StereoVOAdaptiveEnv])
def test_least_squares_refit_is_refused_where_refine_replaces_it(cls):
    for value in (False, True):
        assert _refusal(cls, least_squares_refit=value) == (
            f"{cls.__name__}: least_squares_refit={value!r} would be ignored: refine=True ends with the iterated LM "
            "refinement; least_squares_refit chooses the final step only with refine=False")
    env = cls(**SMALL, refine=False, least_squares_refit=False)
    assert env.estimator_options.least_squares_refit is False


@pytest.mark.parametrize("cls", [StereoVOEnv, StereoVOAdaptiveEnv])
def test_the_gate_quantiles_are_refused_for_msac_and_kept_for_the_methods_that_read_them(cls):
    assert _refusal(cls, gate_probability=0.5) == (
        f"{cls.__name__}: gate_probability=0.5 would be ignored: method 'msac' judges by the stereo reprojection "
        "gate (threshold_px), not by the 3-D Mahalanobis gate whose quantile gate_probability is")
    assert "refine_gate_probability=0.5 would be ignored: method 'msac' has no pixel-gated final refinement" in (
        _refusal(cls, refine_gate_probability=0.5))
    env = cls(**SMALL, method="probabilistic", gate_probability=0.5, refine_gate_probability=0.5)
    assert (env.estimator_options.gate_probability, env.estimator_options.refine_gate_probability) == (0.5, 0.5)
    # probabilistic's pixel gate belongs to its final refinement: none runs without refine and least_squares_refit
    assert "no final refinement runs for its pixel gate" in _refusal(
        cls, method="probabilistic", refine=False, least_squares_refit=False, refine_gate_probability=0.5)


def test_several_unread_options_are_named_together_and_a_bad_value_is_named_first():
    message = _refusal(StereoVOEnv, confidence=0.5, gate_probability=0.5)
    assert message.startswith("StereoVOEnv: confidence=0.5 would be ignored") and "; gate_probability=0.5 would" in message
    assert "confidence must be a finite number in (0, 1), got 1.5" in _refusal(StereoVOEnv, confidence=1.5)


THRESHOLD_IGNORED = ("threshold_px=2.0 would be ignored: method 'probabilistic' judges by the 3-D Mahalanobis gate "
                     "(gate_probability) and selects its final inliers by a Mahalanobis gate too, never by the stereo "
                     "reprojection gate whose threshold threshold_px is")


def _steps(env, n: int = 2) -> list[tuple]:
    """(reward, rotation error, inliers) of ``n`` steps with zero actions from ``reset(seed=1)``."""
    env.reset(seed=1)
    out = []
    for _ in range(n):
        action = np.zeros(env.action_space.shape, dtype=np.float32)
        if isinstance(env, StereoVOAdaptiveEnv):
            action[-1] = 1.0  # stop after each batch: one frame a step or two
        _, reward, _, _, info = env.step(action)
        out.append((reward, info.get("rot_err_deg"), info.get("n_inliers")))
    return out


@pytest.mark.parametrize("cls", [StereoVOEnv, StereoVOAdaptiveEnv])
def test_threshold_px_is_refused_with_a_mahalanobis_judge_unless_the_msac_reward_reads_it(cls):
    assert _refusal(cls, method="probabilistic", threshold_px=2.0) == (
        f"{cls.__name__}: {THRESHOLD_IGNORED}; the environment's reward reads it with reward_mode='msac' only, got "
        "reward_mode='supervised'")
    assert _refusal(cls, method="mlesac", reward_mode="inliers", threshold_px=2.0).startswith(
        f"{cls.__name__}: threshold_px=2.0 would be ignored: method 'mlesac' judges by the 3-D Mahalanobis gate")
    # the msac reward scores under it: the environment's own, kept from an estimator that would not read it
    env = cls(**SMALL, method="probabilistic", reward_mode="msac", threshold_px=2.0)
    plain = cls(**SMALL, method="probabilistic", reward_mode="msac")
    assert env.estimator_options.threshold_px == 2.0
    if cls is StereoVOEnv:
        assert env.estimator_kwargs == plain.estimator_kwargs and "threshold_px" not in env.estimator_kwargs
        assert "threshold_px" in cls(**SMALL, reward_mode="msac", threshold_px=2.0).estimator_kwargs  # msac reads it
    gated, ungated = _steps(env), _steps(plain)
    assert [step[1:] for step in gated] == [step[1:] for step in ungated]  # the same estimates
    assert [step[0] for step in gated] != [step[0] for step in ungated]  # scored under another gate
    # read by the reprojection judges whatever the reward
    assert cls(**SMALL, threshold_px=2.0).estimator_options.threshold_px == 2.0


BANSAC_IGNORES_BATCH_SIZE = (
    "batch_size=8 would be ignored: method {method!r} draws its own batches between belief updates from the first "
    "(bansac_batch; one hypothesis by default, the paper's): batch_size caps them only under "
    "bansac_update='verdict-likelihood', got bansac_update='paper'")


@pytest.mark.parametrize("method", ["bansac", "p-bansac"])
def test_the_environments_batch_size_is_refused_where_the_method_sizes_its_batches_itself(method):
    expected = BANSAC_IGNORES_BATCH_SIZE.format(method=method)
    assert _refusal("vo_gym/StereoVO-v0", method=method, batch_size=8) == f"StereoVOEnv: {expected}"

    class MyEnv(StereoVOEnv):
        pass

    assert _refusal(MyEnv, method=method, batch_size=8) == f"MyEnv: {expected}"
    assert _refusal(StereoVOEnv, method="preemptive", batch_size=8) == (
        "StereoVOEnv: batch_size=8 would be ignored: method 'preemptive' hands its whole set of hypotheses to the "
        "verifier in one batch: batch_size sizes none of its batches")
    # the default, not given (or given as None), is the environment's, never refused: the estimator gets none
    for kwargs in ({}, {"batch_size": None}):
        env = gym.make("vo_gym/StereoVO-v0", **SMALL, method=method, **kwargs).unwrapped
        assert "batch_size" not in env.estimator_kwargs and env.estimator_kwargs["budget"] == 32
    # read where it caps the verdict-likelihood update's batches
    env = StereoVOEnv(**SMALL, method=method, batch_size=2, bansac_update="verdict-likelihood")
    assert env.estimator_kwargs["batch_size"] == 2
    # the in-frame environment draws batch_size hypotheses a step whatever the judge
    adaptive = StereoVOAdaptiveEnv(**SMALL, method=method, batch_size=8)
    adaptive.reset(seed=0)
    action = np.zeros(adaptive.action_space.shape, dtype=np.float32)
    action[-1] = -1.0  # go on
    assert adaptive.step(action)[4]["frame_hypotheses"] == 8


def _frames():
    frames = []
    for outliers in ("default", "hostile"):
        sequence = Sequence(SimulationConfig(n_frames=2, n_correspondences=60, outlier_ratio=0.6, outliers=outliers), 3)
        frames += [sequence.frame(k) for k in (1, 2)]
    return frames


ALTERNATIVES = {"confidence": 0.5, "max_iterations": 2, "first_batch_size": 1, "fail_at_cap": False,
                "least_squares_refit": False, "gate_probability": 0.3, "refine_gate_probability": 0.3,
                "threshold_px": 2.0}


def _inputs(frame, sampling: str) -> dict:
    if sampling == "guided":
        return {"priors": np.exp(frame.scores)}
    return {"order": np.argsort(-frame.scores, kind="stable")}


def _usable_samplings(method: str, frame) -> list[str]:
    """The samplings the method runs with (its declaration, and its recipe: the belief samplers declare
    any input but refuse an order when they run)."""
    out = []
    problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, 0.5)
    for sampling in ("guided", "prosac"):
        try:
            method_spec(method).check_inputs(priors=sampling == "guided", order=sampling == "prosac")
            estimate_problem(problem, method, rng=0, budget=4, **_inputs(frame, sampling))
        except ValueError:
            continue
        out.append(sampling)
    return out


def test_every_option_the_tables_refuse_leaves_the_methods_estimates_unchanged(monkeypatch):
    """The refusals follow what the estimator reads: refusing an option a method does read would take a
    setting away; this catches a declaration that drifts from the recipes."""
    from vo_gym.settings import unread_options

    monkeypatch.setattr(api, "refuse_unread", lambda *args: None)  # the estimate the option would have given

    frames = _frames()
    checked = set()
    for method in available_methods():
        for sampling in _usable_samplings(method, frames[0]):
            for settings in ({"budget": 8, "batch_size": 4}, {"budget": 8, "refine": False},
                             {"budget": None, "refine": False, "least_squares_refit": False}):
                base = {**DEFAULT_ESTIMATOR_OPTIONS, **settings, "noise_sigma": 0.5}
                if base["budget"] is None:
                    base["max_iterations"] = 64
                # the environments' defaults, the cap and the batch size where the method reads them
                # (refine_rounds without refine is refused, preemptive's cap is its M, bansac sizes its batches)
                base = drop_unread(method, base, among=set(base) - set(settings) | {"batch_size"},
                                   order=sampling == "prosac")
                env = StereoVOEnv(**SMALL, method=method, sampling=sampling,
                                  **{k: v for k, v in base.items() if k != "noise_sigma"})
                unread = unread_options(method, env.estimator_options, ALTERNATIVES, sampling)
                for name in unread:
                    if name in base and name != "confidence":
                        continue  # given by these settings themselves
                    for i, frame in enumerate(frames):
                        problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, 0.5)
                        inputs = _inputs(frame, sampling)
                        runs = [estimate_problem(problem, method, rng=np.random.default_rng(i), **inputs, **options)
                                for options in (base, {**base, name: ALTERNATIVES[name]})]
                        a, b = runs
                        assert a.status == b.status and a.n_hypotheses == b.n_hypotheses, (method, sampling, name)
                        assert np.array_equal(a.rotation, b.rotation) and np.array_equal(a.translation, b.translation)
                        assert np.array_equal(a.inliers, b.inliers), (method, sampling, name)
                    checked.add((method.split("+")[0], name))
    # the defaults' refusals were among those checked, and a Mahalanobis judge's threshold_px
    assert {("msac", name) for name in ALTERNATIVES.keys() - {"threshold_px"}} <= checked, sorted(checked)
    assert {(method, "threshold_px") for method in ("probabilistic", "mlesac", "bansac", "ars")} <= checked
    assert ("msac", "threshold_px") not in checked


@pytest.mark.parametrize("kwargs", [{}, {"method": "probabilistic"}, {"sampling": "prosac", "method": "usac"},
                                    {"budget": None, "max_iterations": 64, "confidence": 0.9}])
def test_the_estimator_gets_only_options_its_method_reads_and_the_environments_defaults_count_as_given_by_none(kwargs):
    """The environment gives the estimator what it sets (its defaults, the user's keywords, noise, budget and
    batch size), not every field: a field it never set, such as confidence under the budget, would be refused."""
    from stereovo.estimation import estimate_motion
    from stereovo.estimation.registry import unread_options

    env = StereoVOEnv(**SMALL, **kwargs)
    given = env.estimator_kwargs
    order = env.sampling == "prosac"
    assert unread_options(env.method, env.estimator_options, given, order=order) == {}
    # what it sets, but those its method would not read (usac's LO+ runs whatever local_refit says)
    sets = {"noise_sigma", "budget", "batch_size", *DEFAULT_ESTIMATOR_OPTIONS}
    assert sets - set(given) == set(unread_options(env.method, env.estimator_options, sets, order=order))
    assert sets - set(given) == ({"local_refit"} if env.method == "usac" else set())
    env.reset(seed=0)
    frame = env.sequence.frame(1)
    inputs = _inputs(frame, env.sampling)
    estimate_motion(frame.prev, frame.curr, frame.camera, method=env.method, rng=0, **inputs, **given)  # as bench_env
    env.step(env.action_space.sample())  # and the environment's own estimator runs
