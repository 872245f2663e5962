"""vo_gym.settings: one rule per keyword, the same in both environments, and plain attributes after it."""

from __future__ import annotations

import dataclasses
import pickle

import numpy as np
import pytest

from stereovo.estimation import available_methods, method_spec
from stereovo.options import Integer, Number, check_options, value_repr
from stereovo.simulation import SimulationConfig
from vo_gym.adaptive_env import StereoVOAdaptiveEnv
from vo_gym.env import StereoVOEnv
from vo_gym.names import constructor_keywords
from vo_gym.settings import RULES, SIMULATOR_KEYWORDS, FieldError, Lengths, check_field, check_fields, check_settings

SMALL = dict(n_frames=2, n_correspondences=60)
BOTH = (StereoVOEnv, StereoVOAdaptiveEnv)


def _message(cls, **kwargs) -> str:
    with pytest.raises(ValueError) as err:
        cls(**SMALL, **kwargs)
    return str(err.value)


@pytest.mark.parametrize("kwargs, rule", [
    ({"hypothesis_cost": 1.5}, "hypothesis_cost must be a finite number in [0, 1], got 1.5"),
    ({"hypothesis_cost": -1}, "hypothesis_cost must be a finite number in [0, 1], got -1"),
    ({"action_bound": 0.0}, "action_bound must be a finite number in (0, 3.40282e+38], got 0.0"),
    ({"logit_scale": float("nan")}, "logit_scale must be a finite number > 0, got nan"),
    ({"success_bonus": "0.5"}, "success_bonus must be a finite number in [0, 1], got '0.5'"),
    ({"failure_reward": -2}, "failure_reward must be a finite number in [-1, 1], got -2"),
    ({"reward_mode": "vibes"}, "reward_mode must be one of 'supervised', 'inliers', 'msac', got 'vibes'"),
    ({"batch_size": 0}, "batch_size must be None or an integer >= 1 and <= 1000000000, got 0"),
    ({"max_correspondences": 10}, "max_correspondences=10 is smaller than n_correspondences=60: every frame"),
    ({"estimator_noise_sigma": -1.0}, "estimator_noise_sigma must be None or a finite number in [0.001, 1000] (px)"),
    ({"action_bound": 30.0, "logit_scale": 20.0}, "action_bound * logit_scale must be <= 300 (weights exp(+-300) "
                                                  "stay representable), got 600"),
    ({"noise_sigma": 0.0}, "noise_sigma=0 (noise-free frames) needs estimator_noise_sigma > 0"),
    ({"outlier_ratio": 1.5}, "invalid simulator setting: SimulationConfig.outlier_ratio"),
    ({"threshold_px": -1.0}, "invalid estimator setting:"),
])
def test_a_keyword_both_environments_take_is_refused_by_one_rule_with_one_message(kwargs, rule):
    for cls in BOTH:
        assert _message(cls, **kwargs).startswith(f"{cls.__name__}: {rule}")


def test_prosac_sampling_refuses_a_logit_scale_and_is_not_bound_by_the_softmax_range():
    # PROSAC ranks the action values: no positive scale changes the order and nothing is exponentiated
    with pytest.raises(ValueError) as err:
        StereoVOEnv(**SMALL, sampling="prosac", logit_scale=100)
    assert str(err.value) == ("StereoVOEnv: logit_scale must be 1 with sampling='prosac' (its order ranks the action "
                              "values, which no positive scale changes; the scale applies to sampling='guided'), "
                              "got 100")
    assert StereoVOEnv(**SMALL, sampling="prosac", action_bound=400.0, logit_scale=1).action_bound == 400.0
    assert "action_bound * logit_scale must be <= 300" in _message(StereoVOEnv, action_bound=400.0)


def test_the_constructors_keep_the_checked_values_as_plain_attributes():
    env = StereoVOAdaptiveEnv(**SMALL, batch_size=None, max_hypotheses=12, action_bound=np.float32(2.0),
                              estimator_noise_sigma=2, hypothesis_cost=0)
    assert env.batch_size == 12  # None: the whole cap in one step, as StereoVOEnv's None is the whole budget
    assert type(env.action_bound) is float and env.action_bound == 2.0
    assert type(env.hypothesis_cost) is float and env.hypothesis_cost == 0.0
    assert env.estimator_noise_sigma == 2.0 and env.estimator_options.noise_sigma == 2.0
    assert env.max_correspondences == 60 and env.sim_config.n_frames == 2
    one_shot = StereoVOEnv(**SMALL, budget=8, kitti_lengths=[5, 10])
    assert (one_shot.budget, one_shot.batch_size, one_shot.kitti_lengths) == (8, 8, (5.0, 10.0))


def test_the_adaptive_environment_takes_the_simulators_fields_with_the_simulators_defaults():
    env = StereoVOAdaptiveEnv()
    fields = {f.name: getattr(env.sim_config, f.name) for f in dataclasses.fields(SimulationConfig)}
    assert fields == {f.name: getattr(SimulationConfig(), f.name) for f in dataclasses.fields(SimulationConfig)}
    assert set(SIMULATOR_KEYWORDS) == set(fields)


@pytest.mark.skipif("mlesac" not in available_methods(), reason="the classical methods are not registered")
def test_a_methods_own_options_reach_the_adaptive_search_and_are_checked_as_in_the_one_shot_env():
    env = StereoVOAdaptiveEnv(**SMALL, method="mlesac", mlesac_em_iterations=2)
    # the given option, and every other option of the method at its declared default
    declared = {name: method_spec("mlesac").option_rule(name).default for name in method_spec("mlesac").extra_options}
    assert env.method_options == {**declared, "mlesac_em_iterations": 2}
    for cls in BOTH:
        assert "mlesac_em_iterations" in _message(cls, method="mlesac", mlesac_em_iterations=0)
        with pytest.raises(TypeError, match="sprt_t_m"):
            cls(**SMALL, method="mlesac", sprt_t_m=10)


def test_an_unknown_keyword_is_a_type_error_with_a_hint_in_both():
    for cls, typo, hint in ((StereoVOEnv, "n_correspondence", "n_correspondences"),
                            (StereoVOAdaptiveEnv, "n_correspondence", "n_correspondences"),
                            (StereoVOAdaptiveEnv, "max_hypothesis", "max_hypotheses")):
        with pytest.raises(TypeError, match=rf"'{typo}' \(did you mean '{hint}'\?\)"):
            cls(**{typo: 10})
    with pytest.raises(TypeError) as err:  # the adaptive env's own batch_size is not listed as an estimator option
        StereoVOAdaptiveEnv(zzz=1)
    assert "'batch_size'" not in str(err.value) and "did you mean" not in str(err.value)


def test_every_environment_keyword_has_its_rule_here():
    for cls in BOTH:
        own = set(constructor_keywords(cls)) - set(SIMULATOR_KEYWORDS) - {"method"}
        assert own <= set(RULES), own - set(RULES)


@pytest.mark.parametrize("value", [(), (0.0,), (5.0, -1.0), (float("inf"),), "ab", 3, None, ("x",)])
def test_lengths_refuse_what_is_not_positive_finite_lengths(value):
    with pytest.raises(ValueError, match=r"^E: kitti_lengths must be a non-empty list, tuple or 1-D array of "
                                         r"positive numbers \(m\), got "):
        check_settings("E", kitti_lengths=value)
    assert Lengths().check("x", (1, 2.5)) == (1.0, 2.5)


@pytest.mark.parametrize("value", [(0.9, 0.5), (-0.1, 0.5), (0.2, 1.0), (0.5,), "ab", (0.1, "0.5"), (True, 0.5), None])
def test_a_contamination_range_is_a_pair_within_zero_and_one(value):
    from vo_gym.settings import ContaminationRange

    with pytest.raises(ValueError, match=r"^epsilons must be a \(low, high\) pair with 0 <= low <= high < 1, got "):
        ContaminationRange().check("epsilons", value, prefix="")
    assert ContaminationRange().check("epsilons", [0, np.float32(0.5)], prefix="") == (0.0, 0.5)


LENGTHS_REFUSED = ["123", b"car", {1.0: 2.0}, {5.0}, (True, 2.0), [False], np.array([[1.0, 2.0]]), np.array([True]),
                   np.array(5.0), iter([1.0, 2.0]), range(1, 3), [10**400]]
LENGTHS_ACCEPTED = [([100, 200.5], (100.0, 200.5)), ((np.float32(50.0),), (50.0,)), (np.array([100, 800]), (100.0, 800.0)),
                    ([np.int64(3)], (3.0,))]


def test_lengths_take_only_a_list_tuple_or_1d_array_of_real_numbers():
    # a string, bytes or a dict iterated to numbers: "123" gave (1.0, 2.0, 3.0), b"car" (99.0, 97.0, 114.0)
    for value in LENGTHS_REFUSED:
        with pytest.raises(ValueError, match=r"^StereoVOEnv: kitti_lengths must be a non-empty list, tuple or 1-D "
                                             r"array of positive numbers \(m\), got "):
            StereoVOEnv(**SMALL, kitti_lengths=value)
    for value, lengths in LENGTHS_ACCEPTED:  # their numbers normalised to floats
        env = StereoVOEnv(**SMALL, kitti_lengths=value)
        assert env.kitti_lengths == lengths and all(type(x) is float for x in env.kitti_lengths)


@pytest.mark.parametrize("method", ["bansac", "p-bansac", "ars"])
def test_a_belief_sampler_under_prosac_sampling_is_refused_at_construction(method):
    # it used to be accepted and to fail at the first step, when the recipe was built with the order
    with pytest.raises(ValueError, match=f"method '{method}' with sampling='prosac': .*give priors= \\(or nothing\\)"):
        StereoVOEnv(sampling="prosac", method=method)


@pytest.mark.parametrize("value", [0, -1, 2.5, True, None, "3", 10**400, np.int64(0)], ids=value_repr)
def test_check_fields_refuses_with_check_options_message_and_names_the_field(value):
    declarations = {"seed": Integer(low=0), "frames": Integer(low=1, high=10**9),
                    "rate": Number(low=0.0, low_open=True)}
    values = {"seed": 1, "frames": value, "rate": 0.5}
    with pytest.raises(ValueError) as words:
        check_options(declarations, values, prefix="PPO: ")
    with pytest.raises(FieldError) as err:
        check_fields(declarations, values, prefix="PPO: ")
    assert str(err.value) == str(words.value)
    assert (err.value.field, err.value.prefix) == ("frames", "PPO: ")
    assert err.value.named("--frames") == str(words.value).replace("PPO: frames", "--frames")


def test_check_fields_returns_the_normalised_values_in_the_declarations_order():
    checked = check_fields({"b": Integer(low=0), "a": Number(low=0.0)}, {"a": np.float32(0.5), "b": np.int64(3)})
    assert list(checked) == ["b", "a"] and checked == {"b": 3, "a": 0.5}
    assert type(checked["b"]) is int and type(checked["a"]) is float


def test_a_field_error_names_its_field_whatever_its_words_say():
    err = FieldError("budgets", " must be an integer >= 1, got 0", subject="every budget")
    assert str(err) == "every budget must be an integer >= 1, got 0" and err.field == "budgets"
    assert err.named("--budgets") == "--budgets must be an integer >= 1, got 0"
    # a message that starts with no name gets the caller's name before it
    unnamed = FieldError("methods", "unknown classical method(s): nope", subject="")
    assert str(unnamed) == "unknown classical method(s): nope"
    assert unnamed.named("--methods") == "--methods: unknown classical method(s): nope"
    with pytest.raises(FieldError) as entry:
        check_field("budgets", Integer(low=1), 0, subject="every budget")
    assert (str(entry.value), entry.value.field) == (str(err), "budgets")


def test_a_field_error_keeps_its_field_through_pickle():
    err = pickle.loads(pickle.dumps(FieldError("batch_size", "=9 exceeds the rollout size", prefix="PPO: ")))
    assert (str(err), err.field, err.named("--batch-size")) == (
        "PPO: batch_size=9 exceeds the rollout size", "batch_size", "--batch-size=9 exceeds the rollout size")


@pytest.mark.parametrize("cls, kwargs", [(StereoVOEnv, {"sampling": "prosac"}),
                                         (StereoVOEnv, {"logit_scale": 1e-38}),
                                         (StereoVOAdaptiveEnv, {"logit_scale": 1e-38})])
def test_an_action_bound_past_float32_is_refused_naming_it(cls, kwargs):
    # the action Box is float32: gymnasium refused such a bound without naming action_bound
    message = _message(cls, action_bound=1e39, **kwargs)
    assert message == f"{cls.__name__}: action_bound must be a finite number in (0, 3.40282e+38], got 1e+39"
    assert cls(**SMALL, action_bound=float(np.finfo(np.float32).max), **kwargs).action_space.high[0] == np.finfo(
        np.float32).max
