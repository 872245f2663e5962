"""Fuzzing (hypothesis) of the estimator, the features, the environment and the command line.

Only these outcomes pass: a result that satisfies the invariants (rotation orthonormal with
det +1, finite translation, a bool inlier mask of length N, identity motion on failure), a failed
status, or a ``ValueError`` / ``TypeError`` whose message names the argument at fault. Anything
else (another exception, a NaN in a result, a traceback from argparse's callers) fails.

Examples per test are bounded (``max_examples``) so that the suite adds about a minute on two cores.
"""

from __future__ import annotations

import contextlib
import io
import math
import warnings

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import vo_gym  # noqa: F401
from stereovo.camera import StereoCamera
from stereovo.estimation import available_methods, estimate_motion, method_spec
from stereovo.simulation import SimulationConfig, simulate_frame
from vo_gym_cli import main as cli
from vo_gym.features import FEATURE_BOUND, N_FEATURES, compute_features

CAMERA = StereoCamera()
FUZZ = settings(max_examples=30, deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])

WEIRD_NUMBERS = st.sampled_from([0, 1, -1, 2, 3, 0.5, -0.5, 1.5, 1e-300, 1e300, math.nan, math.inf, -math.inf,
                                 True, False, "0.9", "no", None, complex(1, 1), np.int64(7), np.float32(0.3),
                                 np.bool_(True), [1, 2], 10**30])


def _frame(seed: int, n: int, eps: float):
    return simulate_frame(SimulationConfig(n_correspondences=n, outlier_ratio=eps), np.random.default_rng(seed))


@st.composite
def measurements(draw):
    """prev, curr, scores: a simulated frame, sometimes corrupted the ways callers get it wrong."""
    n = draw(st.integers(3, 60))
    frame = _frame(draw(st.integers(0, 2**16)), n, draw(st.sampled_from([0.0, 0.3, 0.7, 0.95])))
    prev, curr, scores = frame.prev.copy(), frame.curr.copy(), frame.scores.copy()
    kind = draw(st.sampled_from(["none", "none", "nan", "inf", "huge", "zero-disparity", "negative-disparity",
                                 "shape", "rows", "complex", "fortran", "strided", "float32", "int", "list",
                                 "duplicate", "constant", "empty"]))
    row = draw(st.integers(0, n - 1))
    if kind == "nan":
        prev[row, draw(st.integers(0, 3))] = np.nan
    elif kind == "inf":
        curr[row, 0] = np.inf
    elif kind == "huge":
        curr[row] = 1e300
    elif kind == "zero-disparity":
        prev[row, 2] = prev[row, 0]
    elif kind == "negative-disparity":
        curr[row, 2] = curr[row, 0] + 5.0
    elif kind == "shape":
        prev = prev[:, :3]
    elif kind == "rows":
        curr = curr[:-1]
    elif kind == "complex":
        prev = prev.astype(complex)
    elif kind == "fortran":
        prev, curr = np.asfortranarray(prev), np.asfortranarray(curr)
    elif kind == "strided":
        prev = np.repeat(prev, 2, axis=0)[::2]
    elif kind == "float32":
        prev, curr = prev.astype(np.float32), curr.astype(np.float32)
    elif kind == "int":
        prev, curr = np.round(prev).astype(int), np.round(curr).astype(int)
    elif kind == "list":
        prev, curr = prev.tolist(), curr.tolist()
    elif kind == "duplicate":
        prev[:] = prev[0]
        curr[:] = curr[0]
    elif kind == "constant":
        curr = prev.copy()
    elif kind == "empty":
        prev, curr, scores = prev[:0], curr[:0], scores[:0]
    return prev, curr, scores, kind


ARGUMENT_NAMES = ("prev", "curr", "priors", "order", "camera", "noise_sigma", "option", "method", "scores",
                  "previous_motion", "correspondences", "rows", "disparity", "depth")


def _names_an_argument(err: Exception, extra: tuple[str, ...] = ()) -> bool:
    text = str(err)
    return "\n" not in text.strip() and any(name in text for name in ARGUMENT_NAMES + extra)


def _check_estimate(est, n: int) -> None:
    R, t, inliers = np.asarray(est.rotation), np.asarray(est.translation), np.asarray(est.inliers)
    assert R.shape == (3, 3) and t.shape == (3,)
    assert np.all(np.isfinite(R)) and np.all(np.isfinite(t))
    assert np.allclose(R @ R.T, np.eye(3), atol=1e-6) and abs(np.linalg.det(R) - 1.0) < 1e-6
    assert inliers.dtype == bool and inliers.shape == (n,)
    assert est.status == "ok" or est.status.startswith("failed")
    if not est.ok:
        assert np.array_equal(R, np.eye(3)) and np.array_equal(t, np.zeros(3))


SHARED_FUZZ_OPTIONS = ("budget", "max_iterations", "confidence", "noise_sigma", "refine", "batch_size",
                       "min_inliers", "threshold_px", "polish_iterations")


@pytest.mark.parametrize("method", sorted(available_methods()))
@FUZZ
@given(data=measurements(), sampling=st.sampled_from(["none", "priors", "order", "bad-priors", "bad-order"]),
       option=st.sampled_from(SHARED_FUZZ_OPTIONS + ("extra",)), value=WEIRD_NUMBERS, seed=st.integers(0, 2**31))
def test_estimate_motion_fuzz(method, data, sampling, option, value, seed):
    prev, curr, scores, _ = data
    spec = method_spec(method)
    n = len(scores)
    kwargs: dict = {"max_iterations": 200}
    if sampling == "priors" or (sampling == "none" and spec.inputs == "priors"):
        kwargs["priors"] = scores
    elif sampling == "order" or (sampling == "none" and spec.inputs == "order"):
        kwargs["order"] = np.argsort(-scores, kind="stable")
    elif sampling == "bad-priors":
        kwargs["priors"] = np.full(n, value if not isinstance(value, (str, list)) else -1.0, dtype=object)
    elif sampling == "bad-order":
        kwargs["order"] = np.zeros(n, dtype=int)
    name = option
    if option == "extra":
        name = spec.extra_options[seed % len(spec.extra_options)] if spec.extra_options else "budget"
    kwargs[name] = value
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", np.exceptions.ComplexWarning)
            est = estimate_motion(prev, curr, CAMERA, method=method, rng=seed, **kwargs)
    except (ValueError, TypeError) as err:
        assert _names_an_argument(err, (name, method)), repr(err)
        return
    _check_estimate(est, np.shape(prev)[0])


@FUZZ
@given(data=measurements(), noise=WEIRD_NUMBERS,
       motion=st.sampled_from(["none", "identity", "nan", "shape", "bad"]))
def test_compute_features_fuzz(data, noise, motion):
    prev, curr, scores, _ = data
    previous = {"none": None, "identity": (np.eye(3), np.zeros(3)), "nan": (np.full((3, 3), np.nan), np.zeros(3)),
                "shape": (np.eye(2), np.zeros(3)), "bad": "fast"}[motion]
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", np.exceptions.ComplexWarning)
            feats = compute_features(prev, curr, scores, CAMERA, noise, previous)
    except (ValueError, TypeError) as err:
        assert _names_an_argument(err), repr(err)
        return
    n = np.shape(prev)[0]
    assert feats.shape == (n, N_FEATURES) and feats.dtype == np.float32
    assert np.all(np.isfinite(feats)) and np.all(np.abs(feats) <= FEATURE_BOUND)


ENV_KEYWORDS = ("sampling", "reward_mode", "max_correspondences", "action_bound", "logit_scale", "success_bonus",
                "hypothesis_cost", "failure_reward", "n_frames", "noise_sigma", "outlier_ratio", "score_auc",
                "z_min", "speed", "method", "budget", "batch_size", "estimator_noise_sigma", "refine", "confidence",
                "min_inliers", "local_refit", "bogus_keyword", "preset", "world", "outlier_mix")


@FUZZ
@given(keyword=st.sampled_from(ENV_KEYWORDS), value=WEIRD_NUMBERS | st.sampled_from(["msac", "prosac", "guided", "car"]),
       seed=st.integers(0, 2**31), action=st.sampled_from(["zeros", "random", "nan", "inf-pad", "shape", "complex",
                                                            "huge", "text"]))
def test_env_make_reset_step_fuzz(keyword, value, seed, action):
    try:
        env = gym.make("vo_gym/StereoVO-v0", n_frames=2, n_correspondences=40, budget=4, **{keyword: value})
    except (ValueError, TypeError) as err:
        assert keyword in str(err), repr(err)
        return
    obs, _ = env.reset(seed=seed)
    space = env.observation_space
    assert space.contains(obs)
    m = env.action_space.shape[0]
    rng = np.random.default_rng(seed)
    candidate = {
        "zeros": np.zeros(m, np.float32), "random": rng.normal(size=m).astype(np.float32),
        "nan": np.full(m, np.nan), "inf-pad": np.concatenate([np.zeros(40), np.full(m - 40, -np.inf)]),
        "shape": np.zeros(m + 1), "complex": np.zeros(m, complex), "huge": np.full(m, 1e300), "text": "logits",
    }[action]
    for _ in range(2):
        try:
            obs, reward, terminated, truncated, info = env.step(candidate)
        except ValueError as err:
            assert "action" in str(err), repr(err)
            return
        assert space.contains(obs) and -1.0 <= reward <= 1.0 and math.isfinite(reward) and not terminated
    assert truncated and "trajectory" in info


OPTION_TEXTS = st.sampled_from(["-1", "0", "1", "2", "0.5", "1e3", "nan", "inf", "-inf", "abc", "", "1,2", "a,b",
                                "0.3:0.9", "2:1", "1e309", "ppo", "msac", "/dev/null", "--x", " ", "0x10"])


@pytest.mark.parametrize("command", list(cli.COMMANDS))
@FUZZ
@given(picks=st.lists(st.tuples(st.integers(0, 1000), OPTION_TEXTS), min_size=1, max_size=3))
def test_cli_argument_parsing_fuzz(command, picks):
    """Parsing alone (no command runs): either it parses, or one line naming an argument and exit 2."""
    parser = cli.build_parser([command])
    sub = next(a for a in parser._actions if a.dest == "command").choices[command]
    options = [a for a in sub._actions if a.option_strings and a.dest != "help"]
    argv = [command]
    for index, text in picks:
        action = options[index % len(options)]
        argv.append(action.option_strings[-1])
        if action.nargs != 0:
            argv.append(text)
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            parser.parse_args(argv)
        except SystemExit as exc:
            assert exc.code == 2, (argv, exc.code)
            lines = err.getvalue().strip().splitlines()
            assert len(lines) == 1 and lines[0].startswith(f"vo-gym {command}: error:"), (argv, lines)
            assert "--" in lines[0] or "argument" in lines[0], (argv, lines)
