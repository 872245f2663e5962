"""One contract for options (stereovo.options): Integer, Boolean, Number and Choice refuse a value
naming it, and worker counts and seeds follow one rule in every layer."""

from __future__ import annotations

import math
import re
import sys

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
    np.array([[True, False]] * 3), np.arange(6, dtype=np.uint8).reshape(3, 2), np.full((3, 2), np.nan, np.float16),
    np.ma.masked_array(np.ones((3, 2))), [[1, 2], [3, 4], [5, 6]],
])
def test_real_array_gives_numpys_float64_conversion(value):
    """The fast path for real ndarrays returns what np.asarray(value, float64) returns (the array itself for float64)."""
    from stereovo.options import real_array

    out = real_array("x", value, ("N", 2))
    expected = np.asarray(value, dtype=np.float64)
    assert type(out) is type(expected) and out.dtype == np.float64
    np.testing.assert_array_equal(out, expected)
    assert (out is value) == (expected is value)
    with pytest.raises(ValueError, match=r"^x must have shape \(N, 3\), one row, got \(3, 2\)$"):
        real_array("x", value, ("N", 3), per="one row")


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
