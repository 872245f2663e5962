"""stereovo.benchmark.claims: each paper's claim judged agree / disagree / not measured on hand-made summaries."""

from __future__ import annotations

from stereovo import benchmark as bm
from stereovo.benchmark import AGREES, DISAGREES, NOT_MEASURED, BenchmarkSummary
from tests.support.benchmark import summary_stats, make_summary, judge_claims


def test_claims_not_measured_when_methods_absent():
    claims = judge_claims(make_summary({"ransac": summary_stats()}))
    assert len(claims) == 11
    assert all(c.verdict == NOT_MEASURED for c in claims.values())
    assert "prosac not in this run" in claims["prosac-iterations"].numbers


def test_claims_iterations_agree_and_disagree():
    agree = judge_claims(make_summary({"ransac": summary_stats(), "prosac": summary_stats(mean_hypotheses=100.0),
                              "mlesac": summary_stats(), "guided-mlesac": summary_stats(mean_hypotheses=380.0)}))
    assert agree["prosac-iterations"].verdict == AGREES
    assert "pooled" in agree["prosac-iterations"].numbers and "x0.25" in agree["prosac-iterations"].numbers
    assert agree["guided-mlesac-iterations"].verdict == DISAGREES  # 0.95x is no cut
    assert agree["guided-ransac-iterations"].verdict == NOT_MEASURED


def test_guided_claims_are_judged_at_the_most_informative_auc():
    overall = {"ransac": summary_stats(), "ransac+guided": summary_stats(mean_hypotheses=390.0)}
    by_auc = {"ransac": {0.5: summary_stats(), 0.9: summary_stats(mean_hypotheses_to_best=100.0)},
              "ransac+guided": {0.5: summary_stats(mean_hypotheses=400.0),
                                0.9: summary_stats(mean_hypotheses=200.0, mean_hypotheses_to_best=50.0)}}
    c = judge_claims(BenchmarkSummary(list(overall), overall, by_auc=by_auc))["guided-ransac-iterations"]
    assert c.verdict == AGREES and c.numbers.startswith("at AUC 0.9:") and "at AUC 0.5: x1.00" in c.numbers
    assert "final best was found 50 vs 100 (x0.50)" in c.numbers
    useless = {m: {0.5: per[0.5]} for m, per in by_auc.items()}
    c = judge_claims(BenchmarkSummary(list(overall), overall, by_auc=useless))["guided-ransac-iterations"]
    assert c.verdict == NOT_MEASURED and "uninformative" in c.numbers


def test_guided_claims_list_the_ratio_of_each_epsilon_at_that_auc():
    rows = []
    for eps, guided_hyps in ((0.2, 90), (0.8, 300)):
        for method, hyps, ok in (("ransac", 100 if eps == 0.2 else 1000, True), ("ransac+guided", guided_hyps, eps == 0.2)):
            for auc in (0.75, 0.9):
                h = hyps if auc == 0.9 else 2 * hyps
                rows.append({"method": method, "epsilon": eps, "n": 500, "score_auc": auc, "success": ok,
                             "status": "ok", "n_hypotheses": h, "n_hypotheses_to_best": h, "rot_err_deg": 0.1,
                             "trans_err_m": 0.01, "precision": 1.0, "recall": 1.0, "n_point_checks": 500 * h,
                             "time_s": 1e-3})
    summary = bm.summarize(rows)
    assert summary.by_epsilon_auc["ransac+guided"][(0.8, 0.9)]["mean_hypotheses"] == 300
    c = judge_claims(summary)["guided-ransac-iterations"]
    assert "by epsilon at AUC 0.9 (mean hypotheses, success): 0.2 x0.90 (100.0 % vs 100.0 %), " \
           "0.8 x0.30 (0.0 % vs 100.0 %)" in c.numbers


def test_claims_time_and_accuracy():
    overall = {
        "ransac": summary_stats(),
        "lo-ransac": summary_stats(median_time_ms=80.0, median_rot_err_deg=0.03),
        "r-ransac": summary_stats(median_time_ms=30.0, mean_point_checks=2e4),
        "waldsac": summary_stats(median_time_ms=55.0),
    }
    c = judge_claims(make_summary(overall))
    assert c["lo-ransac-time"].verdict == AGREES and c["lo-ransac-accuracy"].verdict == AGREES
    assert c["r-ransac-time"].verdict == AGREES and "2e+04" in c["r-ransac-time"].numbers
    assert c["waldsac-time"].verdict == DISAGREES
    by_eps = {m: {0.2: summary_stats(median_time_ms=10.0), 0.8: summary_stats(median_time_ms=t)}
              for m, t in (("ransac", 200.0), ("waldsac", 100.0))}
    c = judge_claims(make_summary(overall, by_eps))
    assert "at epsilon 0.8: 100.0 ms vs 200.0 ms (x0.50)" in c["waldsac-time"].numbers
    overall["lo-ransac"] = summary_stats(median_time_ms=52.0, median_rot_err_deg=0.03, success_rate=0.9)
    c = judge_claims(make_summary(overall))
    assert c["lo-ransac-time"].verdict == DISAGREES
    assert c["lo-ransac-accuracy"].verdict == DISAGREES  # more accurate but 10 points less successful


def test_claims_preemptive():
    def summary(pre_times, pre_success, ransac_success=(1.0, 0.9)):
        by_eps = {
            "preemptive": {0.2: summary_stats(median_time_ms=pre_times[0], success_rate=pre_success[0]),
                           0.8: summary_stats(median_time_ms=pre_times[1], success_rate=pre_success[1])},
            "ransac": {0.2: summary_stats(median_time_ms=10.0, success_rate=ransac_success[0]),
                       0.8: summary_stats(median_time_ms=100.0, success_rate=ransac_success[1])},
        }
        return judge_claims(make_summary({"ransac": summary_stats(), "preemptive": summary_stats()}, by_eps))

    c = summary((40.0, 45.0), (1.0, 0.6))
    assert c["preemptive-constant-time"].verdict == AGREES and "ransac max/min x10.00" in c["preemptive-constant-time"].numbers
    assert c["preemptive-unreliable"].verdict == AGREES
    c = summary((40.0, 90.0), (1.0, 0.95))
    assert c["preemptive-constant-time"].verdict == DISAGREES
    assert c["preemptive-unreliable"].verdict == DISAGREES
    light_only = {"preemptive": {0.2: summary_stats(), 0.4: summary_stats(success_rate=0.5)}}
    c = judge_claims(make_summary({"preemptive": summary_stats()}, light_only))
    assert c["preemptive-unreliable"].verdict == NOT_MEASURED  # never heavily contaminated


def test_claims_clique():
    def summary(clique_success, times):
        # robustness is judged against the enhanced ransac row; textbook ransac fails at 0.8 here
        by_eps = {"inlier-detection": {0.2: summary_stats(), 0.8: summary_stats(success_rate=clique_success)},
                  "ransac+polish+refit+lm": {0.2: summary_stats(), 0.8: summary_stats(success_rate=0.7)},
                  "ransac": {0.2: summary_stats(), 0.8: summary_stats(success_rate=0.1)}}
        by_n = {"inlier-detection": {n: summary_stats(median_time_ms=t) for n, t in times.items()},
                "ransac": {100: summary_stats(median_time_ms=10.0), 1000: summary_stats(median_time_ms=100.0)}}
        return judge_claims(make_summary({"ransac": summary_stats(), "inlier-detection": summary_stats(),
                                 "ransac+polish+refit+lm": summary_stats()}, by_eps, by_n))

    c = summary(0.68, {100: 1.0, 1000: 100.0})
    assert c["clique-robust"].verdict == AGREES
    assert c["clique-quadratic"].verdict == AGREES and "slope 2.00" in c["clique-quadratic"].numbers
    assert "ransac slope 1.00" in c["clique-quadratic"].numbers
    c = summary(0.5, {100: 10.0, 1000: 100.0})
    assert c["clique-robust"].verdict == DISAGREES and c["clique-quadratic"].verdict == DISAGREES
    # 50 % beats the failing textbook ransac (10 %): that comparison is context, not the verdict
    assert "ransac+polish+refit+lm 70.0 %" in c["clique-robust"].numbers
    assert "ransac 10.0 %" in c["clique-robust"].context and "agrees" in c["clique-robust"].context
    c = summary(0.9, {500: 10.0})
    assert c["clique-quadratic"].verdict == NOT_MEASURED


def test_claims_markdown_lists_every_verdict():
    claims = bm.check_claims(make_summary({"ransac": summary_stats(), "prosac": summary_stats(mean_hypotheses=10.0)}))
    text = bm.claims_markdown(claims)
    assert "1 agree, 0 do not agree, 10 not measured" in text
    assert text.count("**not measured**") == 20 and "**agrees**" in text


def test_claims_name_their_reference_frames_and_enhanced_pair():
    overall = {"ransac": summary_stats(), "lo-ransac": summary_stats(median_time_ms=80.0, frames=30),
               "ransac+polish+refit+lm": summary_stats(median_time_ms=40.0),
               "lo-ransac+polish+lm": summary_stats(median_time_ms=40.0)}
    c = judge_claims(make_summary(overall))["lo-ransac-time"]
    assert c.verdict == AGREES  # 80 vs 50 ms against textbook ransac
    assert "30 frames" in c.measured_on and "textbook `ransac`" in c.reference
    # with the additions on both sides the times are equal: the context says so, with its own verdict
    assert "x1.00" in c.context and DISAGREES in c.context
    text = bm.claims_markdown([c])
    assert c.measured_on in text and c.context in text
    # a claim that cannot be measured carries no frames and no diagnosis
    absent = judge_claims(make_summary({"ransac": summary_stats()}), )["waldsac-time"]
    assert absent.verdict == NOT_MEASURED and absent.measured_on == "" and absent.diagnosis == ""


def test_accuracy_claim_fails_when_translation_alone_is_worse():
    # Rotation 40 % better, success equal, but the median translation error doubled: a median error
    # more than 1 / 0.9 of the reference's is "worse", so the claim disagrees.
    overall = {"ransac": summary_stats(median_rot_err_deg=0.05, median_trans_err_m=0.01),
               "lo-ransac": summary_stats(median_rot_err_deg=0.03, median_trans_err_m=0.02)}
    c = judge_claims(make_summary(overall))["lo-ransac-accuracy"]
    assert c.verdict == DISAGREES and "(x2.00)" in c.numbers
    # The same translation within 1 / 0.9 (x1.10) is no worse: the rotation gain makes it agree.
    overall["lo-ransac"] = summary_stats(median_rot_err_deg=0.03, median_trans_err_m=0.011)
    assert judge_claims(make_summary(overall))["lo-ransac-accuracy"].verdict == AGREES


def test_accuracy_claim_agrees_on_success_gain_alone():
    # Equal median errors (x1.00 both), success 8 points higher (>= the 2-point margin): "gains accuracy".
    overall = {"ransac": summary_stats(success_rate=0.9),
               "lo-ransac": summary_stats(success_rate=0.98)}
    c = judge_claims(make_summary(overall))["lo-ransac-accuracy"]
    assert c.verdict == AGREES and c.numbers.count("(x1.00)") == 2
    # One point higher is under the margin: nothing is better, so it disagrees.
    overall["lo-ransac"] = summary_stats(success_rate=0.91)
    assert judge_claims(make_summary(overall))["lo-ransac-accuracy"].verdict == DISAGREES
