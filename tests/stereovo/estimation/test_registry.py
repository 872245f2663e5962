"""The method registry: every classical method is registered with a description and a reference,
and variants refuse unknown enhancements and duplicates."""

from __future__ import annotations

import numpy as np
import pytest

from stereovo import available_methods
from stereovo.estimation.registry import method_spec, register_variant
from tests.support.methods import CLASSICAL


def test_classical_methods_are_registered_with_description_and_reference():
    methods = available_methods()
    for name in CLASSICAL:
        assert name in methods
        spec = method_spec(name)
        assert len(spec.description) > 20 and spec.reference
    assert method_spec("waldsac").extra_options == ("sprt_t_m", "sprt_epsilon0", "sprt_delta0", "sprt_chunk")
    assert "lo_inner_iterations" in method_spec("usac").extra_options


def test_register_variant_refuses_unknown_enhancements_and_duplicates():
    with pytest.raises(ValueError, match="enhancements must be some of"):
        register_variant("ransac", "turbo")
    with pytest.raises(ValueError, match="already registered"):
        register_variant("ransac", "polish")


def test_split_options_repeats_an_earlier_result_and_refuses_what_it_refused():
    from stereovo.estimation.registry import method_spec, split_options

    spec = method_spec("bansac")
    shared, extra = split_options(spec, {"max_iterations": 40, "bansac_batch": 4})
    again, extra_again = split_options(spec, {"bansac_batch": 4, "max_iterations": 40})
    assert again is shared and extra_again == extra
    extra_again["bansac_batch"] = 99  # a caller's copy: the next call gets the checked value
    assert split_options(spec, {"max_iterations": 40, "bansac_batch": 4})[1] == extra
    # equal-hashing values of other types are checked anew, not answered from the cache
    for bad in (True, 40.0, np.int64(-1)):
        with pytest.raises(ValueError, match="max_iterations"):
            split_options(spec, {"max_iterations": bad, "bansac_batch": 4})
    assert split_options(spec, {"max_iterations": np.int64(40), "bansac_batch": 4})[0].max_iterations == 40
    # a refused option stays refused on every call
    for _ in range(2):
        with pytest.raises(ValueError, match="confidence"):
            split_options(spec, {"confidence": 1.5})
    # another method with the same options gets its own defaults
    assert split_options(method_spec("probabilistic"), {"max_iterations": 40})[0].runner_up_refit == 0.5
    assert split_options(method_spec("ransac"), {"max_iterations": 40})[0].runner_up_refit is None
