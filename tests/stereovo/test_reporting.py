"""The reports' shared helpers (stereovo.reporting) and the baseline figures drawn with them."""

from __future__ import annotations

import hashlib

import numpy as np
import pytest

from stereovo import benchmark as bm
from stereovo.reporting import (
    MAX_LINES_PER_PANEL,
    check_plot_format,
    format_number,
    format_percent,
    wilson_interval,
)


def test_wilson_interval_matches_hand_computed_values():
    # k = 5 of n = 10 at 95 %: centre (0.5 + z^2/20) / (1 + z^2/10) = 0.5, half-width 0.2634
    low, high = wilson_interval(5, 10)
    assert (float(low), float(high)) == pytest.approx((0.23659, 0.76341), abs=1e-5)
    low, high = wilson_interval([0, 10], [10, 10])
    assert low.tolist() == pytest.approx([0.0, 0.72247], abs=1e-5)
    assert high.tolist() == pytest.approx([0.27753, 1.0], abs=1e-5)
    low, high = wilson_interval(0, 0)
    assert np.isnan(low) and np.isnan(high)


def test_wilson_interval_covers_the_true_rate_as_promised():
    rng = np.random.default_rng(7)
    for p, n in ((0.3, 20), (0.9, 50), (0.98, 100)):
        k = rng.binomial(n, p, size=4000)
        low, high = wilson_interval(k, n, 0.95)
        coverage = np.mean((low <= p) & (p <= high))
        # Wilson's coverage oscillates around the nominal level; 4000 draws put the estimate within +-1 %
        assert 0.92 <= coverage <= 0.985, (p, n, coverage)


@pytest.mark.parametrize("bad", [dict(successes=3, trials=2), dict(successes=-1, trials=2),
                                 dict(successes=1, trials=2, confidence=1.0)])
def test_wilson_interval_refuses_impossible_counts(bad):
    with pytest.raises(ValueError, match="successes|confidence"):
        wilson_interval(**bad)


def test_formats_and_plot_format_check():
    assert format_percent(0.1234) == "12.3 %" and format_percent(None) == "n/a"
    assert format_number(3.14159, ".2f") == "3.14" and format_number(None) == "n/a"
    assert check_plot_format(".PDF") == "pdf"
    with pytest.raises(ValueError, match="'tiff'"):
        check_plot_format("tiff")


def test_panels_hold_at_most_eight_lines_each_family_and_every_method():
    methods = bm.benchmark_methods() + ["ransac+new-step", "some-new-method"]
    panels = bm.plot_panels(methods)
    assert all(len(members) <= MAX_LINES_PER_PANEL for _, members in panels)
    assert all(members[0] == bm.REFERENCE_METHOD for _, members in panels)
    drawn = [m for _, members in panels for m in members if m != bm.REFERENCE_METHOD]
    assert sorted(drawn) == sorted(set(methods) - {bm.REFERENCE_METHOD})  # each once
    for _, members in panels:
        assert len({bm.method_family(m) for m in members[1:]}) == 1  # one family a panel
    assert bm.method_family("ransac+guided") == "sampling"
    assert bm.method_family("ransac+new-step") == "enhancements"
    assert bm.method_family("some-new-method") == "other"
    assert bm.plot_panels(["ransac"]) == [(bm.FAMILY_TITLES["scoring"], ["ransac"])]


def _rows(methods, frames=4):
    rng = np.random.default_rng(1)
    rows = []
    for m in methods:
        for e in (0.2, 0.8):
            for n in (100, 200):
                for _ in range(frames):
                    ok = bool(rng.random() < 1 - e / 2)
                    rows.append(dict(method=m, epsilon=e, n=n, score_auc=0.75, noise_sigma=0.5, outlier_kind="random",
                                     success=ok, rot_err_deg=0.01 if ok else 5.0, trans_err_m=0.002 if ok else 0.5,
                                     precision=1.0, recall=0.9, n_hypotheses=int(10 / (1 - e)), n_point_checks=100,
                                     time_s=1e-3 * n / 100, status="ok"))
    return rows


def test_figures_have_a_legend_per_panel_and_its_own_bound(monkeypatch, tmp_path):
    methods = ["ransac", "msac", "prosac", "ransac+guided", "ransac+lm", "r-ransac"]
    rows = _rows(methods)
    summary = bm.summarize(rows)
    saved = {}
    monkeypatch.setattr(bm.plots, "save_figure", lambda fig, path: saved.setdefault(path.name, fig) and path)
    bm.write_plots(rows, summary, tmp_path)
    panels = bm.plot_panels(summary.methods)
    success = saved["success_vs_epsilon.png"].axes
    assert len(success) == len(panels)
    for ax, (_, members) in zip(success, panels):
        assert [t.get_text() for t in ax.get_legend().get_texts()] == members
        assert len(ax.collections) == len(members)  # one Wilson band per line
    cdf = saved["error_cdf.png"].axes
    assert len(cdf) == 2 * len(panels)
    for (_, members), ax_rot, ax_trans in zip(panels, cdf[::2], cdf[1::2]):
        assert len(ax_rot.texts) == len(ax_trans.texts) == 0  # no label drawn over the curves
        assert ax_rot.get_legend() is None  # the row's one legend sits beside the translation panel
        legend = [t.get_text() for t in ax_trans.get_legend().get_texts()]
        assert legend[:len(members)] == members
        assert legend[len(members)].startswith("success bound 0.05 m") and legend[-1] == "success bound 1 deg"
        assert [line.get_xdata()[0] for line in (ax_rot.get_lines()[-1], ax_trans.get_lines()[-1])] == [1.0, 0.05]


@pytest.mark.parametrize("fmt", ["pdf", "svg"])
def test_vector_figures_are_written_and_reproducible(tmp_path, fmt):
    rows = _rows(["ransac", "msac"], frames=2)
    summary = bm.summarize(rows)
    first = bm.write_plots(rows, summary, tmp_path / "a", fmt=fmt)
    second = bm.write_plots(rows, summary, tmp_path / "b", fmt=fmt)
    assert [p.name for p in first] == list(bm.plot_files(fmt))
    digest = [hashlib.sha256(p.read_bytes()).hexdigest() for p in first]
    assert digest == [hashlib.sha256(p.read_bytes()).hexdigest() for p in second]
    assert first[0].read_bytes()[:5] == (b"%PDF-" if fmt == "pdf" else b"<?xml")


def test_write_outputs_refuses_an_unknown_format_before_writing(tmp_path):
    with pytest.raises(ValueError, match="'jpeg'"):
        bm.write_outputs(_rows(["ransac"], frames=1), tmp_path / "out", plot_format="jpeg")
    assert not (tmp_path / "out").exists()


def test_the_command_line_offers_exactly_the_library_formats(tmp_path):
    from stereovo.reporting import PLOT_FORMATS
    from vo_gym_cli.main import main
    from vo_gym_cli.commands import baselines

    assert baselines.PLOT_FORMATS == PLOT_FORMATS
    with pytest.raises(SystemExit) as exit_info:
        main(["baselines", "--format", "tiff", "--out", str(tmp_path / "x")])
    assert exit_info.value.code == 2


def test_baselines_writes_its_figures_in_the_chosen_format(tmp_path, capsys):
    from vo_gym_cli.main import main

    out = tmp_path / "run"
    argv = ["baselines", "--methods", "ransac,msac", "--frames-per-cell", "1", "--epsilons", "0.5", "--aucs", "0.75",
            "--ns", "60", "--sigmas", "0.5", "--outlier-kinds", "random", "--no-progress", "--out", str(out)]
    assert main([*argv, "--format", "svg"]) == 0
    assert all((out / name).stat().st_size > 0 for name in bm.plot_files("svg"))
    assert not any((out / name).exists() for name in bm.PLOT_FILES)
    assert "error_cdf.svg" in capsys.readouterr().out
    assert main(["baselines", "--report-only", str(out), "--format", "pdf"]) == 0
    assert all((out / name).read_bytes()[:5] == b"%PDF-" for name in bm.plot_files("pdf"))


def test_evaluate_writes_its_figures_in_the_chosen_format(tmp_path):
    pytest.importorskip("torch")
    from agents.evaluation.report import PLOT_NAMES
    from vo_gym_cli.main import main

    out = tmp_path / "eval"
    assert main(["evaluate", "--agent", "uniform", "--episodes", "1", "--frames-per-episode", "2", "--epsilons", "0.8",
                 "--budgets", "4", "--budget", "4", "--sweep-epsilon", "0.8", "--n", "80", "--methods", "ransac", "--max-iterations", "50",
                 "--no-progress", "--format", "pdf", "--out", str(out)]) == 0
    assert all((out / f"{name}.pdf").read_bytes()[:5] == b"%PDF-" for name in PLOT_NAMES)
    assert not any((out / f"{name}.png").exists() for name in PLOT_NAMES)


@pytest.mark.parametrize("confidence", [0.95, 0.68])
def test_a_success_lines_band_is_the_wilson_interval_at_its_confidence(confidence):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from stereovo.reporting import plot_success, wilson_interval

    fig, ax = plt.subplots()
    try:
        plot_success(ax, [0.2, 0.5], [0.5, 0.9], [20, 100], "a", {"color": "C0"}, confidence=confidence)
        (band,) = ax.collections
        vertices = band.get_paths()[0].vertices
        low, high = wilson_interval(np.array([10.0, 90.0]), np.array([20.0, 100.0]), confidence)
        for x, lo, hi in zip((0.2, 0.5), low, high):
            ys = vertices[np.isclose(vertices[:, 0], x), 1]
            np.testing.assert_allclose([ys.min(), ys.max()], [100 * lo, 100 * hi], rtol=1e-12)
    finally:
        plt.close(fig)
