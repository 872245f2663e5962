"""agents.evaluation.report on hand-made rows: the hypotheses needed for the success target are the smallest
budget of the budget sweep whose success rate reaches the target."""

from __future__ import annotations

from agents.evaluation.report import hypotheses_label, summarize_evaluation
from agents.evaluation.setup import KIND_ADAPTIVE, KIND_AGENT, KIND_FIXED, EvalConfig


def _rows(method: str, kind: str, budget: int, successes: int, frames: int = 4, epsilon: float = 0.8) -> list[dict]:
    """``frames`` rows of ``method`` at ``budget`` and ``epsilon``, the first ``successes`` of them successes."""
    return [{"method": method, "kind": kind, "epsilon": epsilon, "budget": budget, "score_auc": 0.75,
             "status": "ok", "success": i < successes, "rot_err_deg": 0.1, "trans_err_m": 0.01, "precision": 1.0,
             "recall": 1.0, "n_hypotheses": budget, "n_point_checks": 100 * budget, "time_s": 0.001}
            for i in range(frames)]


def test_the_hypotheses_needed_are_the_smallest_budget_that_reaches_the_target():
    # Target 0.75 at epsilon 0.8 over the budgets 2, 4 and 8 (four frames each: 3 of 4 is exactly 0.75).
    config = EvalConfig(epsilons=(0.8,), budget=8, budgets=(8, 2, 4), sweep_epsilon=0.8, success_target=0.75,
                        methods=("msac",))
    success = {  # successes of 4 at budgets 2, 4, 8
        "early": (4, 4, 4),  # every budget reaches the target: the smallest, 2
        "late": (2, 3, 4),  # 4 (3 of 4, exactly the target) and 8 reach it: 4
        "dip": (3, 2, 4),  # 2 and 8 reach it, 4 does not: 2
        "never": (2, 2, 2),  # none: None, shown as "> 8"
    }
    rows = []
    for method, counts in success.items():
        kind = KIND_FIXED if method == "late" else KIND_AGENT
        for budget, k in zip((2, 4, 8), counts):
            rows += _rows(method, kind, budget, k)
    rows += _rows("early", KIND_AGENT, 2, 0, epsilon=0.5)  # another contamination: not the sweep's
    rows += _rows("msac (adaptive)", KIND_ADAPTIVE, 8, 4)  # its own stop: no budget to find
    summary = summarize_evaluation(rows, config)
    needed = summary["hypotheses_for_success"]
    assert needed["methods"] == {"early": 2, "late": 4, "dip": 2, "never": None}
    assert (needed["target"], needed["epsilon"], needed["max_budget"]) == (0.75, 0.8, 8)
    assert [hypotheses_label(summary, m) for m in ("early", "late", "dip", "never")] == ["2", "4", "2", "> 8"]
