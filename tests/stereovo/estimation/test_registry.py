"""The method registry: every classical method is registered with a description and a reference,
and variants refuse unknown enhancements and duplicates."""

from __future__ import annotations

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
