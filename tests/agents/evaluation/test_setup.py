"""agents.evaluation.setup's EvalConfig: an environment keyword that one of its own fields also sets
must agree with it, so that the frames and the report's header show one value."""

from __future__ import annotations

import pytest

from agents.evaluation.setup import EvalConfig


@pytest.mark.parametrize("fields, needle", [
    ({"score_auc": 0.6, "env_kwargs": {"score_auc": 0.9}}, "env_kwargs' score_auc=0.9 contradicts score_auc=0.6"),
    ({"max_iterations": 100, "env_kwargs": {"max_iterations": 50}},
     "env_kwargs' max_iterations=50 contradicts max_iterations=100"),
])
def test_a_keyword_that_contradicts_its_field_is_refused(fields, needle):
    with pytest.raises(ValueError, match=needle):
        EvalConfig(**fields)


def test_a_keyword_that_agrees_with_its_field_or_has_none_is_kept():
    assert EvalConfig(score_auc=0.9, env_kwargs={"score_auc": 0.9}).env_kwargs_for(0.5, 8)["score_auc"] == 0.9
    # score_auc None: the keyword is the one value there is
    assert EvalConfig(env_kwargs={"score_auc": 0.9}).env_kwargs_for(0.5, 8)["score_auc"] == 0.9
