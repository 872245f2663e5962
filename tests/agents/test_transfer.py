"""agents.transfer: the transfer matrix's cells, reports and domain hook, on a tiny configuration."""

from __future__ import annotations

import numpy as np
import pytest

from agents import transfer
from agents.transfer import (
    CLASSICAL_ROWS,
    DOMAINS,
    OWN_STOP,
    TransferConfig,
    build_rows,
    model_card_block,
    read_results,
    regenerate_command,
    register_domain,
    replace_block,
    run_cell,
    simulator_domain,
    transfer_markdown,
    write_csv,
)
from stereovo.estimation import estimate_motion
from stereovo.metrics import frame_metrics
from stereovo.reporting import wilson_interval
from tests.support.images import rendered
from vo_gym.settings import DEFAULT_ESTIMATOR_OPTIONS

TINY = TransferConfig(budgets=(4,), sequences=1, cap=24, samplers=("ngransac-supervised", "adaptive-pg-prior"))


@pytest.fixture(scope="module")
def cell():
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        return run_cell("hostile", 0.5, TINY, build_rows(TINY))
    finally:
        torch.set_num_threads(threads)


def test_a_cell_has_every_row_and_point_with_its_interval(cell):
    keys = {(r["sampler"], r["point"]) for r in cell}
    names = {"ngransac-supervised", "adaptive-pg-prior", "BANSAC (score priors)", "ARS (score priors)",
             "PROSAC (by score)", "uniform (MSAC)"}
    assert keys == {(n, p) for n in names for p in ("4", OWN_STOP)}
    for r in cell:
        assert r["frames"] == 10 and 0 <= r["successes"] <= 10
        assert r["ci_low"] <= r["success"] <= r["ci_high"]
        if r["point"] == "4":
            assert r["mean_hypotheses"] == 4
        elif r["kind"] == "in-frame":
            assert r["mean_hypotheses"] <= 64
        else:
            assert r["mean_hypotheses"] <= TINY.cap
    learned = {r["sampler"]: r for r in cell if r["point"] == "4"}
    assert learned["ngransac-supervised"]["kind"] == "one-shot" and learned["adaptive-pg-prior"]["kind"] == "in-frame"


def test_a_cells_successes_rate_and_interval_are_those_of_its_frames_recounted(cell, monkeypatch):
    # The uniform rows (MSAC at 4 hypotheses and under its own stop) recounted by hand on the frames the cell
    # drew: each sequence's estimates from one generator seeded by (the cell's seed, the sequence), every
    # estimate judged by frame_metrics, the rate with its Wilson interval.
    drawn = []
    hostile = DOMAINS["hostile"]

    def recording(epsilon, seed, sequences):
        for sequence in hostile(epsilon, seed, sequences):
            drawn.append((seed, sequence))
            yield sequence

    monkeypatch.setitem(DOMAINS, "hostile", recording)
    uniform = [row for row in build_rows(TINY) if row[0] == "uniform (MSAC)"]
    assert [(row[0], row[2]) for row in uniform] == [("uniform (MSAC)", "4"), ("uniform (MSAC)", OWN_STOP)]
    results = run_cell("hostile", 0.5, TINY, uniform)
    assert len(drawn) == TINY.sequences == 1
    (_, method, _), = [r for r in CLASSICAL_ROWS if r[0] == "uniform (MSAC)"]
    recounts = []
    for point, budget in (("4", 4), (OWN_STOP, None)):
        successes, hypotheses = 0, 0
        for k, (seed, sequence) in enumerate(drawn):
            rng = np.random.default_rng([seed, k])
            for frame in sequence:
                # the cap of the own stop; a budget is the stop itself and reads none (the estimator refuses it)
                cap = {"max_iterations": TINY.cap, "fail_at_cap": False} if budget is None else {}
                est = estimate_motion(frame.prev, frame.curr, frame.camera, method=method, rng=rng, budget=budget,
                                      **cap, **DEFAULT_ESTIMATOR_OPTIONS)
                successes += bool(frame_metrics(est, frame.truth).success)
                hypotheses += est.n_hypotheses
        recounts.append(successes)
        low, high = wilson_interval(successes, 10)
        # the same frames in the module's whole cell (every row) as in this run of the uniform rows alone
        for r in (next(r for r in results if r["point"] == point),
                  next(r for r in cell if (r["sampler"], r["point"]) == ("uniform (MSAC)", point))):
            assert r["frames"] == 10 and r["successes"] == successes
            assert r["success"] == successes / 10
            assert (r["ci_low"], r["ci_high"]) == (float(low), float(high))
            assert r["mean_hypotheses"] == hypotheses / 10
    # the recount tells a count from a tally of frames: at 4 hypotheses some frames fail
    assert recounts[0] < 10


def test_a_cells_frames_depend_on_the_seed_domain_and_contamination_alone():
    a = next(DOMAINS["default"](0.8, 3, 1))
    b = next(DOMAINS["default"](0.8, 3, 1))
    c = next(DOMAINS["hostile"](0.8, 3, 1))
    np.testing.assert_array_equal(a[0].prev, b[0].prev)
    assert not np.array_equal(a[0].curr, c[0].curr)
    assert len(a) == 10 and [f.index for f in a] == list(range(1, 11))


def test_reports_round_trip_through_the_csv(cell, tmp_path):
    path = write_csv(cell, tmp_path / "t.csv")
    back = read_results(path)
    assert len(back) == len(cell) and back[0]["frames"] == 10 and back[0]["seed"] == TINY.seed
    command = regenerate_command(back)
    assert command == "python -m agents.transfer --jobs 2 --publish --frames 10 --domains hostile --epsilons 0.5 " \
                      "--budgets 4 --cap 24"
    table = transfer_markdown(back, command)
    assert f"Regenerate: `{command}`" in table and "#### hostile (transfer)" in table
    card = model_card_block(back, "ngransac-supervised", command)
    assert card.count("| hostile (transfer) | 0.5 |") == 1
    assert "Not in the transfer matrix" in model_card_block(back, "no-such", command)


def test_replace_block_needs_one_block():
    text = f"a\n{transfer.BEGIN}\nold\n{transfer.END}\nb"
    assert replace_block(text, "new", "x") == f"a\n{transfer.BEGIN}\nnew\n{transfer.END}\nb"
    with pytest.raises(ValueError, match="needs one"):
        replace_block("no block", "new", "x.md")


def test_a_registered_domain_joins_the_matrix(monkeypatch):
    monkeypatch.setitem(DOMAINS, "weak-scores", simulator_domain(score_auc=0.55))
    with pytest.raises(ValueError, match="new non-empty string"):
        register_domain("default", simulator_domain())
    with pytest.raises(ValueError, match="callable"):
        register_domain("other", 3)
    config = TransferConfig(domains=("weak-scores",), budgets=(4,), sequences=1, samplers=("ppo",), classical=False)
    rows = run_cell("weak-scores", 0.5, config, build_rows(config))
    assert {r["point"] for r in rows} == {"4", OWN_STOP} and all(r["domain"] == "weak-scores" for r in rows)
    with pytest.raises(ValueError, match="unknown domain 'nowhere'"):
        run_cell("nowhere", 0.5, config, [])


def test_the_rendered_domain_gives_front_end_frames_at_the_cells_contamination():
    rendered(preset="car", n_frames=1, resolution="vga", seed=0).close()  # or a skip naming what is missing
    frames = transfer.rendered_domain(resolution="vga", n_frames=2)
    first = [list(seq) for seq in frames(0.8, 11, 2)]
    again = [list(seq) for seq in frames(0.8, 11, 2)]
    assert [len(seq) for seq in first] == [2, 2]
    for seq, seq_again in zip(first, again):
        for frame, frame_again in zip(seq, seq_again):
            assert abs(frame.truth.outlier_ratio - 0.8) <= 2.0 / frame.n
            assert np.array_equal(frame.curr, frame_again.curr) and np.array_equal(frame.scores, frame_again.scores)
    # two sequences are two drives, not one drive twice
    assert not np.array_equal(first[0][0].prev[:5], first[1][0].prev[:5])


def test_a_one_domain_rerun_merges_into_a_published_matrix(cell, tmp_path):
    # how one domain is re-measured and published: run it alone (--domains hostile), then
    # --merge PUBLISHED.csv RERUN.csv [--publish]; the rerun's rows replace that domain's rows in
    # place, every other domain's rows are kept as they were, in the registry's order
    default = [{**r, "domain": "default"} for r in cell]
    published = write_csv(cell + default, tmp_path / "published.csv")  # written out of order on purpose
    rerun = [{**r, "successes": 10 - r["successes"], "success": 1 - r["success"],
              "ci_low": 1 - r["ci_high"], "ci_high": 1 - r["ci_low"]} for r in cell]  # Wilson intervals mirror
    rerun_csv = write_csv(rerun, tmp_path / "rerun" / "transfer.csv")
    merged = transfer.merge([read_results(published), read_results(rerun_csv)])
    assert [r["domain"] for r in merged] == ["default"] * len(cell) + ["hostile"] * len(cell)
    assert [(r["sampler"], r["point"]) for r in merged[len(cell):]] == [(r["sampler"], r["point"]) for r in cell]
    assert merged[:len(cell)] == read_results(published)[len(cell):]  # the kept rows, unchanged
    assert [r["successes"] for r in merged[len(cell):]] == [10 - r["successes"] for r in cell]
    assert transfer.main(["--merge", str(published), str(rerun_csv), "--out", str(tmp_path / "out")]) == 0
    assert read_results(tmp_path / "out" / "transfer.csv") == merged
    # the kept rows' text is what was published (the CSV round trip changes no digit)
    kept = (tmp_path / "out" / "transfer.csv").read_text().splitlines()[1:len(cell) + 1]
    assert kept == published.read_text().splitlines()[len(cell) + 1:]
