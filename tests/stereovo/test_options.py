"""One contract for options (stereovo.options): Integer, Boolean, Number and Choice refuse a value
naming it, and worker counts and seeds follow one rule in every layer."""

from __future__ import annotations

import math
import re
import sys
from fractions import Fraction

import numpy as np
import pytest

from stereovo.options import Boolean, Choice, Integer, Number, OptionError


def test_integer_accepts_integers_only():
    rule = Integer(low=1)
    assert rule.check("k", 3) == 3 and type(rule.check("k", np.int64(3))) is int
    for bad in (True, np.bool_(True), 1.5, 3.0, "3", None, float("inf"), complex(3, 0), 0):
        with pytest.raises(OptionError, match=r"^option k must be an integer >= 1, got "):
            rule.check("k", bad)
    assert Integer(allow_none=True).check("k", None) is None


def test_a_refusal_carries_the_name_and_what_it_says_of_the_value_and_keeps_them_through_pickle():
    import pickle

    with pytest.raises(OptionError) as caught:
        Number(low=0.0, high=1.0).check("gamma", 1.5, prefix="PPO: ")
    err = pickle.loads(pickle.dumps(caught.value))
    assert err.name == "gamma" and str(err) == f"PPO: gamma{err.rule}"
    assert err.rule.startswith(" must be ") and err.rule.endswith(", got 1.5")


def test_boolean_accepts_bools_only():
    rule = Boolean()
    assert rule.check("b", True) is True and rule.check("b", np.bool_(False)) is False
    for bad in ("no", "False", 0, 1, None, 1.0):
        with pytest.raises(OptionError, match=r"^option b must be True or False, got "):
            rule.check("b", bad)


def test_number_is_finite_real_and_in_range():
    rule = Number(low=0.0, high=1.0, low_open=True, high_open=True)
    assert rule.check("p", 0.5) == 0.5 and rule.check("p", np.float32(0.25)) == 0.25
    for bad in (0.0, 1.0, math.nan, math.inf, -math.inf, "0.9", True, complex(0.5, 0), None, [0.5]):
        with pytest.raises(OptionError, match=r"^option p must be a finite number in \(0, 1\), got "):
            rule.check("p", bad)


def test_choice_lists_the_valid_values():
    with pytest.raises(OptionError, match=r"must be one of 'a', 'b', got 'c'"):
        Choice(choices=("a", "b")).check("mode", "c")


@pytest.mark.parametrize("value", [0, -1, 1.5, math.nan, True, "2"])
def test_worker_counts_and_seeds_of_every_layer_follow_the_contract(value):
    """One rule for counts everywhere: the backends, the benchmark grid, the agents' evaluation and sweeps."""
    from agents.evaluation.setup import EvalConfig
    from agents.sweep_config import MetricSpec
    import dataclasses

    from stereovo.benchmark import DEFAULT_GRID, check_seed
    from stereovo.trials.backend import LocalBackend, chunked

    cases = [
        (lambda: LocalBackend(value), r"^workers must be an integer >= 1, got "),
        (lambda: chunked([], value), r"^chunk size must be an integer >= 1, got "),
        (lambda: dataclasses.replace(DEFAULT_GRID, frames_per_cell=value), r"^BenchmarkGrid\.frames_per_cell must be an integer >= 1"),
        (lambda: EvalConfig(episodes=value), r"^episodes must be an integer >= 1, got "),
        (lambda: MetricSpec(budget=value), r"^sweep metric\.budget must be an integer >= 1 and <= 1000000000, got "),
    ]
    if value != 0:  # 0 is a valid seed
        cases += [(lambda: check_seed(value), r"^seed must be an integer >= 0, got "),
                  (lambda: EvalConfig(seed=value), r"^seed must be an integer >= 0, got ")]
    for make, message in cases:
        with pytest.raises(ValueError, match=message):
            make()


@pytest.mark.parametrize("value", [
    np.arange(6.0).reshape(3, 2), np.arange(6, dtype=np.float32).reshape(3, 2) / 7, np.arange(6).reshape(3, 2),
    np.arange(6, dtype=np.uint8).reshape(3, 2), np.full((3, 2), np.nan, np.float16),
    np.ma.masked_array(np.ones((3, 2))), [[1, 2], [3, 4], [5, 6]], ((1, 2.5), (np.float32(3), np.int8(4)), (5, 6)),
    np.array([[1, 2.5], [Fraction(1, 3), np.int64(4)], [5, 6]], dtype=object),
])
def test_real_array_gives_numpys_float64_conversion(value):
    """The fast path for real ndarrays returns what np.asarray(value, float64) returns (the array itself for
    float64); so does the slow path for lists, tuples and object arrays of real numbers."""
    from stereovo.options import real_array

    out = real_array("x", value, ("N", 2))
    expected = np.asarray(value, dtype=np.float64)
    assert type(out) is type(expected) and out.dtype == np.float64
    np.testing.assert_array_equal(out, expected)
    assert (out is value) == (expected is value)
    with pytest.raises(ValueError, match=r"^x must have shape \(N, 3\), one row, got \(3, 2\)$"):
        real_array("x", value, ("N", 3), per="one row")


M = 5  # the arrays' length in the real_array tests


@pytest.mark.parametrize("value,got", [
    (None, "None"),
    (np.ones(M, bool), "ndarray of dtype bool"),
    (np.zeros(M, "datetime64[s]"), "ndarray of dtype datetime64[s]"),
    (np.zeros(M, "timedelta64[ms]"), "ndarray of dtype timedelta64[ms]"),
    (np.array(["1.5"] * M), "ndarray of dtype <U3"),
    (np.array([b"2"] * M), "ndarray of dtype |S1"),
    (np.zeros(M, [("x", "f8")]), "ndarray of dtype [('x', '<f8')]"),
    (np.ma.masked_array(np.ones(M, bool)), "MaskedArray of dtype bool"),
    ([True] * M, "list holding True"),
    ([1.0, 2.0, np.True_, 4.0, 5.0], "list holding np.True_"),  # numpy reads the list as float64
    ((0.5,) * 4 + (None,), "tuple holding None"),
    (["1"] * M, "list holding '1'"),
    ([np.timedelta64(1, "s")] * M, "list holding np.timedelta64(1,'s')"),
    (np.array([1.0, None, 2.0, 3.0, 4.0], dtype=object), "ndarray holding None"),
    (np.array([1.0, 2.0, False, 3.0, 4.0], dtype=object), "ndarray holding False"),
    (np.array(["7"] * M, dtype=object), "ndarray holding '7'"),
    (True, "True"),
    (np.datetime64("2024-01-01"), "np.datetime64('2024-01-01')"),
])
def test_real_array_refuses_bools_dates_strings_void_and_none_naming_what_it_got(value, got):
    """numpy casts all of these to float64 (None to NaN, True to 1, a date to its count of seconds),
    so they were taken for numbers; refused like other non-numbers, naming the argument and the value."""
    from stereovo.options import real_array

    with pytest.raises(ValueError) as err:
        real_array("the action", value, (M,), what=f"a numeric array of shape ({M},)", prefix="Env: ")
    assert str(err.value) == f"Env: the action must be a numeric array of shape ({M},), got {got}"


@pytest.mark.parametrize("value", [[[1.0, 2.0], [3.0]], [10**400] * M])
def test_real_array_refuses_ragged_lists_and_integers_too_large_for_a_float_in_its_own_words(value):
    """numpy's own ValueError ('inhomogeneous shape') and an OverflowError (no ValueError) came out."""
    from stereovo.options import real_array

    with pytest.raises(ValueError) as err:
        real_array("x", value, (M,))
    assert str(err.value) == f"x must be a numeric array of shape ({M},) of numbers, got list"


def test_numpy_timedelta64_is_no_integer_and_no_number():
    """np.timedelta64 is an np.signedinteger: Integer and Number took it for a number, then failed
    converting it with a TypeError (int() of a datetime.timedelta) instead of naming it."""
    from stereovo.options import is_integer, is_real

    value = np.timedelta64(3, "s")
    assert not is_integer(value) and not is_real(value)
    with pytest.raises(OptionError, match=r"^option k must be an integer >= 1, got np\.timedelta64\(3,'s'\)$"):
        Integer(low=1).check("k", value)
    with pytest.raises(OptionError, match=r"^option x must be a finite number, got np\.timedelta64\(3,'s'\)$"):
        Number().check("x", value)


def _callers_of_real_array():
    """Each caller of real_array: the shape of the array argument it checks, a call with it (the
    other arguments valid) and the start of its message."""
    import gymnasium as gym

    import vo_gym  # noqa: F401
    from stereovo import estimate_motion
    from stereovo.estimation import StereoProblem
    from tests.support.frames import CAMERA, noise_free_pair
    from vo_gym.features import compute_features

    prev, curr = noise_free_pair(np.random.default_rng(0), np.eye(3), np.array([0, 0, -1.0]), 30)

    def env_step(env_id):
        def step(action):
            env = gym.make(env_id, n_frames=2)
            env.reset(seed=0)
            try:
                env.step(action)
            finally:
                env.close()
        return step

    return {
        "StereoVO-v0": ((500,), env_step("vo_gym/StereoVO-v0"),
                        "StereoVOEnv: the action must be a numeric array of shape (500,), got "),
        "StereoVOAdaptive-v0": ((501,), env_step("vo_gym/StereoVOAdaptive-v0"),
                                "StereoVOAdaptiveEnv: the action must be a numeric array of shape (501,), got "),
        "estimate_motion priors": ((30,), lambda a: estimate_motion(prev, curr, CAMERA, "guided-mlesac", priors=a),
                                   "priors must be an array of real weights, got "),
        "StereoProblem prev": ((30, 4), lambda a: StereoProblem.build(a, curr, CAMERA),
                               "prev must be a numeric (N, 4) array of (uL, vL, uR, vR) pixels, got "),
        "compute_features scores": ((30,), lambda a: compute_features(prev, curr, a, CAMERA, 0.5, None),
                                    "scores must be a finite (30,) array of numbers, got "),
    }


@pytest.mark.parametrize("caller", ["StereoVO-v0", "StereoVOAdaptive-v0", "estimate_motion priors",
                                    "StereoProblem prev", "compute_features scores"])
def test_every_caller_of_real_array_refuses_bool_date_and_none_arrays(caller):
    """An environment's action np.ones(M, bool) or np.zeros(M, 'datetime64[s]') was taken as values
    1 and 0 (such an action skips the environment's float fast path into real_array's cast), and
    None was refused as 'must have shape (500,) ..., got ()'; so it was for priors, measurements
    and scores."""
    shape, call, message = _callers_of_real_array()[caller]
    for value, got in [(np.ones(shape, bool), "ndarray of dtype bool"),
                       (np.zeros(shape, "datetime64[s]"), "ndarray of dtype datetime64[s]"),
                       (None, "None")]:
        if value is None and caller == "estimate_motion priors":
            continue  # priors=None is no priors
        if value is not None and value.dtype == bool and caller == "compute_features scores":
            continue  # whether a bool mask may stand for scores is compute_features' to say (it casts or not)
        with pytest.raises(ValueError) as err:
            call(value)
        assert str(err.value) == message + got


@pytest.mark.parametrize("rule,rule_text", [(Number(low=0.0), ">= 0"), (Number(), ""), (Number(low=0.0, high=1.0), "in \\[0, 1\\]")],
                         ids=["low", "unbounded", "range"])
@pytest.mark.parametrize("exponent,text", [(400, "~1e+400 (an integer of 401 digits)"),
                                           (-400, "~-1e+400 (an integer of 401 digits)"),
                                           (5000, "~1e+5000 (an integer of 5001 digits)")])
def test_number_refuses_integers_too_large_for_a_float_naming_them_briefly(rule, rule_text, exponent, text):
    """float(10**400) raises OverflowError: such an integer is refused as a number out of range,
    and written by its magnitude (its repr would be 401 digits; past 4300 Python refuses it)."""
    value = 10 ** abs(exponent) * (1 if exponent > 0 else -1)
    expected = rf"^option confidence must be a finite number{' ' + rule_text if rule_text else ''}, got {re.escape(text)}$"
    with pytest.raises(OptionError, match=expected):
        rule.check("confidence", value)


def test_number_keeps_large_integers_that_a_float_holds():
    big = int(sys.float_info.max)  # the largest integer that converts to a finite float
    assert Number().check("x", big) == big and type(Number().check("x", big)) is int
    assert Number(low=0.0).check("x", 10**300) == 10**300
    with pytest.raises(OptionError, match=r"got ~1\.8e\+309 \(an integer of 310 digits\)$"):
        Number().check("x", big * 10)


def test_is_finite_real():
    from stereovo.options import is_finite_real

    assert is_finite_real(1) and is_finite_real(np.float32(0.5)) and is_finite_real(10**300)
    for bad in (10**400, math.nan, math.inf, np.float64("inf"), True, "1", None, complex(1, 0), [1]):
        assert not is_finite_real(bad)


def test_value_repr_abbreviates_only_enormous_values():
    from stereovo.options import value_repr

    for ordinary in (0.5, -1, 10**59, "abc", None, (0.2, 0.4), [1, 2], {"random": 0.5}, (1,), np.float64(0.25)):
        assert value_repr(ordinary) == repr(ordinary)
    assert value_repr((0, 10**400)) == "(0, ~1e+400 (an integer of 401 digits))"
    assert value_repr({"random": 10**400}) == "{'random': ~1e+400 (an integer of 401 digits)}"
    assert value_repr(10**400 - 1) == "~1e+400 (an integer of 400 digits)"
    long = value_repr("x" * 1000)
    assert len(long) == 200 and long.endswith("...")
    assert value_repr(tuple(range(20)) + (10**5000,)) == "<tuple object>"  # a repr that raises: the type, no error
