"""agents.LearnedEstimator: a learned sampler of either kind on a user's own arrays.

Frames are hand-built here (points, a known motion, the camera's projection, noise, random
outliers), so nothing of the simulator's frame objects reaches the estimator; the last test runs
the estimator on the very frames of the shipped-sampler test and asks for its margin over uniform.
"""

from __future__ import annotations

import importlib.resources
import shutil

import numpy as np
import pytest
import torch

from agents import LearnedEstimator, LearnedMotionEstimate
from agents.samplers import load_sampler
from stereovo import StereoCamera, estimate_motion
from stereovo.geometry import rotation_error
from stereovo.metrics import frame_metrics
from vo_gym.env import DEFAULT_ESTIMATOR_OPTIONS

ONE_SHOT, IN_FRAME = "ngransac-supervised", "adaptive-pg-prior"


pytestmark = pytest.mark.usefixtures("one_torch_thread")


def rotation_about_y(deg: float) -> np.ndarray:
    a = np.radians(deg)
    return np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])


def hand_built_frame(rng: np.random.Generator, n: int = 300, outliers: float = 0.5, camera: StereoCamera | None = None,
                     R: np.ndarray | None = None, t: np.ndarray | None = None):
    """``(prev, curr, camera, scores, inlier, R, t)``: N matches of static points moved by ``(R, t)``
    (``x_k = R x_{k-1} + t``), 0.5 px noise; a share ``outliers`` of the rows get an unrelated
    ``curr`` measurement and lower scores."""
    camera = StereoCamera() if camera is None else camera
    R = rotation_about_y(1.0) if R is None else R
    t = np.array([0.05, 0.0, -1.0]) if t is None else t
    points = np.column_stack([rng.uniform(-8, 8, n), rng.uniform(-2, 2, n), rng.uniform(6, 40, n)])
    prev = camera.project(points) + rng.normal(0, 0.5, (n, 4))
    curr = camera.project(points @ R.T + t) + rng.normal(0, 0.5, (n, 4))
    bad = rng.random(n) < outliers
    fake = np.column_stack([rng.uniform(-8, 8, n), rng.uniform(-2, 2, n), rng.uniform(6, 40, n)])
    curr[bad] = camera.project(fake[bad])
    prev[:, 3], curr[:, 3] = prev[:, 1], curr[:, 1]  # rectified: one row per match
    scores = np.clip(np.where(bad, rng.beta(2, 3, n), rng.beta(3, 2, n)), 1e-3, 1 - 1e-3)
    return prev, curr, camera, scores, ~bad, R, t


def pose_is_right(estimate, R, t) -> bool:
    return (estimate.ok and np.degrees(rotation_error(estimate.rotation, R)) < 0.5
            and np.linalg.norm(estimate.translation - t) < 0.05)


def shipped_path(name: str):
    return importlib.resources.files("agents").joinpath("checkpoints", f"{name}.pt")


@pytest.mark.parametrize("sampler", [ONE_SHOT, IN_FRAME, "ppo"])
def test_both_kinds_by_name_recover_a_hand_built_motion(sampler):
    rng = np.random.default_rng(1)
    estimator = LearnedEstimator(sampler)
    for _ in range(3):
        prev, curr, camera, scores, inlier, R, t = hand_built_frame(rng)
        est = estimator.estimate(prev, curr, camera, scores)
        assert isinstance(est, LearnedMotionEstimate)
        assert est.sampler == sampler and est.sampler_kind == estimator.kind
        assert pose_is_right(est, R, t), (est.status, est.rotation, est.translation)
        precision = np.count_nonzero(est.inliers & inlier) / est.n_inliers
        assert precision > 0.95 and est.n_inliers > 0.6 * inlier.sum()
        assert est.covariance.shape == (6, 6) and est.time_s > 0
    # the last success is the next frame's constant-velocity prediction; reset forgets it
    np.testing.assert_array_equal(estimator.previous_motion[0], est.rotation)
    estimator.reset()
    assert estimator.previous_motion is None


@pytest.mark.parametrize("name", [ONE_SHOT, IN_FRAME])
def test_a_checkpoint_path_of_either_kind(tmp_path, name):
    mine = tmp_path / f"my-{name}.pt"
    with importlib.resources.as_file(shipped_path(name)) as source:
        shutil.copy(source, mine)
    estimator = LearnedEstimator(mine, budget=8)
    assert estimator.name == f"my-{name}" and estimator.kind == ("one-shot" if name == ONE_SHOT else "in-frame")
    prev, curr, camera, scores, _, R, t = hand_built_frame(np.random.default_rng(2))
    est = estimator.estimate(prev, curr, camera, scores)
    assert pose_is_right(est, R, t) and est.n_hypotheses == 8 and est.sampler == f"my-{name}"
    # a policy load_sampler returned is shared as it is (load once, many estimators)
    shared = load_sampler(mine)
    assert LearnedEstimator(shared, budget=4).policy is shared


@pytest.mark.parametrize("sampler", [ONE_SHOT, IN_FRAME])
def test_same_seed_same_estimate(sampler):
    frames = [hand_built_frame(np.random.default_rng(10 + i), outliers=0.7)[:4] for i in range(3)]

    def run(**kw):
        return LearnedEstimator(sampler, seed=5, **kw).estimate_sequence(frames)

    first, again = run(), run()
    for a, b in zip(first, again):
        np.testing.assert_array_equal(a.rotation, b.rotation)
        np.testing.assert_array_equal(a.translation, b.translation)
        np.testing.assert_array_equal(a.inliers, b.inliers)
        assert a.n_hypotheses == b.n_hypotheses
    other = LearnedEstimator(sampler, seed=6).estimate_sequence(frames)
    assert any(not np.array_equal(a.rotation, b.rotation) for a, b in zip(first, other))
    # an explicit seed per call gives the same as a generator of that seed
    est = LearnedEstimator(sampler)
    a = est.estimate(*frames[0], rng=3)
    est.reset()
    b = est.estimate(*frames[0], rng=np.random.default_rng(3))
    np.testing.assert_array_equal(a.rotation, b.rotation)


@pytest.mark.parametrize("sampler", [ONE_SHOT, IN_FRAME])
def test_any_n_missing_scores_unusable_rows_and_hopeless_frames(sampler):
    estimator = LearnedEstimator(sampler)
    rng = np.random.default_rng(3)
    for n in (40, 700):
        prev, curr, camera, scores, _, R, t = hand_built_frame(rng, n=n, outliers=0.3)
        estimator.reset()
        assert pose_is_right(estimator.estimate(prev, curr, camera, None), R, t)  # no scores: uninformative
    prev, curr, camera, scores, _, R, t = hand_built_frame(rng, n=200, outliers=0.3)
    prev[:5, 2] = prev[:5, 0] + 3.0  # negative disparity: no depth
    est = estimator.estimate(prev, curr, camera, scores)
    assert pose_is_right(est, R, t)
    assert est.unusable[:5].all() and not est.unusable[5:].any() and not est.inliers[:5].any()
    assert est.inliers.shape == (200,)
    tiny = estimator.estimate(prev[5:7], curr[5:7], camera, scores[5:7])
    assert tiny.status.startswith("failed: too few") and np.array_equal(tiny.rotation, np.eye(3))
    assert tiny.covariance is None
    with pytest.raises(ValueError, match="scores"):
        estimator.estimate(prev, curr, camera, scores[:-1])
    with pytest.raises(ValueError, match="prev"):
        estimator.estimate(prev[:, :3], curr, camera, scores)


def test_one_shot_stop_and_budget_follow_the_options():
    prev, curr, camera, scores, _, R, t = hand_built_frame(np.random.default_rng(4), outliers=0.7)
    own = LearnedEstimator(ONE_SHOT).estimate(prev, curr, camera, scores)
    # the prior-aware stop: the bound takes the all-inlier chance of a draw from the sampler's priors,
    # far above the uniform one at 30 % inliers
    uniform = estimate_motion(prev, curr, camera, method="msac", rng=0, **DEFAULT_ESTIMATOR_OPTIONS)
    assert pose_is_right(own, R, t) and own.counters["stop_guided"] == 1
    assert own.n_hypotheses < uniform.n_hypotheses / 2, (own.n_hypotheses, uniform.n_hypotheses)
    assert LearnedEstimator(ONE_SHOT, budget=40).estimate(prev, curr, camera, scores).n_hypotheses == 40
    inframe = LearnedEstimator(IN_FRAME, budget=12).estimate(prev, curr, camera, scores)
    assert inframe.n_hypotheses == 12
    assert LearnedEstimator(IN_FRAME).estimate(prev, curr, camera, scores).n_hypotheses <= 64


@pytest.mark.parametrize("method, needs", [("prosac", "order="), ("guided-mlesac", "priors=")])
def test_a_method_an_in_frame_sampler_cannot_drive_is_refused_at_construction(method, needs):
    # the in-frame search draws from the sampler's weights and passes the method neither input, so
    # the method's recipe would fail in the first estimate instead
    with pytest.raises(ValueError) as info:
        LearnedEstimator(IN_FRAME, method=method)
    assert str(info.value).startswith(f"method '{method}' needs {needs}")
    assert f"in-frame sampler '{IN_FRAME}' draws from its own weights" in str(info.value)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("method", ["bansac", "lo-ransac", "preemptive"])
def test_the_recipe_reaches_a_method_where_it_reads_it_and_the_callers_own_unread_options_are_refused(method):
    # the environments' recipe sets local_refit=False and, for a one-shot search, its own batches: bansac and
    # lo-ransac refit every new best anyway, bansac draws its own batches, preemptive its M in one
    prev, curr, camera, scores, _, R, t = hand_built_frame(np.random.default_rng(4), outliers=0.3)
    for sampler, budget in ((ONE_SHOT, None), (ONE_SHOT, 16), (IN_FRAME, None)):
        assert LearnedEstimator(sampler, method=method, budget=budget).estimate(prev, curr, camera, scores).ok
    with pytest.raises(ValueError, match=f"method '{method}': local_refit=True would be ignored: method '{method}' "):
        LearnedEstimator(ONE_SHOT, method=method, local_refit=True)


def test_in_frame_stop_options_work_or_are_refused():
    prev, curr, camera, scores, *_ = hand_built_frame(np.random.default_rng(8), outliers=0.8)
    # max_iterations caps the sampler's own stop as it caps the one-shot adaptive stop; confidence
    # 0.999 alone would let the search run on to the training cap of 64
    capped = LearnedEstimator(IN_FRAME, confidence=0.999, max_iterations=2)
    assert capped.max_hypotheses == 2
    assert capped.estimate(prev, curr, camera, scores).n_hypotheses == 2
    # a cap above the training cap leaves it (the transfer matrix passes one cap to every row)
    assert LearnedEstimator(IN_FRAME, max_iterations=256, fail_at_cap=False).max_hypotheses == 64
    # a cap above max_iterations' default (10 000) stays when max_iterations is not given
    assert LearnedEstimator(IN_FRAME, max_hypotheses=20_000).max_hypotheses == 20_000
    # a budget is the stop itself, for both kinds: drawn in full above max_iterations (docs/algorithms.md); the
    # in-frame cap stays read (the sampler sees hypotheses spent / cap), a one-shot budget is the core's, which
    # refuses the cap of the adaptive stop it replaces, and neither kind reads a confidence under a budget
    est = LearnedEstimator(IN_FRAME, budget=8, max_iterations=3).estimate(prev, curr, camera, scores)
    assert est.n_hypotheses == 8
    assert LearnedEstimator(ONE_SHOT, budget=8).estimate(prev, curr, camera, scores).n_hypotheses == 8
    with pytest.raises(ValueError, match="max_iterations=3 would be ignored: a fixed budget .budget=8."):
        LearnedEstimator(ONE_SHOT, budget=8, max_iterations=3)
    for sampler in (ONE_SHOT, IN_FRAME):
        with pytest.raises(ValueError) as info:
            LearnedEstimator(sampler, budget=8, confidence=0.5)
        assert str(info.value) == (f"confidence 0.5: with budget=8 {sampler!r} draws exactly that many hypotheses "
                                   "and no stop runs for a confidence to set (budget=None stops at it)")
    # what the in-frame search does is what its options say
    options = LearnedEstimator(IN_FRAME, confidence=0.95).options
    assert (options.fail_at_cap, options.confidence) == (False, 0.95)
    with pytest.raises(ValueError) as info:
        LearnedEstimator(IN_FRAME, first_batch_size=1)
    assert str(info.value) == (f"first_batch_size 1: in-frame sampler '{IN_FRAME}' draws batch_size hypotheses a "
                               "batch from the first (default 4, its training batch)")
    with pytest.raises(ValueError) as info:
        LearnedEstimator(IN_FRAME, fail_at_cap=True)
    assert str(info.value).startswith(f"fail_at_cap True: in-frame sampler '{IN_FRAME}' ends a search that reaches "
                                      "its cap on the best-supported hypothesis")
    with pytest.raises(ValueError, match="fail_at_cap must be True or False, got 0"):
        LearnedEstimator(IN_FRAME, fail_at_cap=0)


def test_priors_on_raw_matches_are_the_estimators_weights():
    prev, curr, camera, scores, inlier, R, t = hand_built_frame(np.random.default_rng(5), outliers=0.6)
    policy = load_sampler(ONE_SHOT)
    priors = policy.priors(prev, curr, camera, scores)
    assert priors.shape == (300,) and priors.max() == 1.0 and priors.min() > 0
    assert priors[inlier].mean() > 5 * priors[~inlier].mean()  # it tells inliers apart
    est = estimate_motion(prev, curr, camera, method="msac", priors=priors, budget=16, rng=0, **DEFAULT_ESTIMATOR_OPTIONS)
    assert pose_is_right(est, R, t)
    with pytest.raises(ValueError, match="observation dict"):
        policy.act(np.zeros((10, 14), np.float32))


def test_priors_without_scores_follow_the_rows_and_match_the_estimators_recipe():
    # N 200: below the 256 rigid-consistency anchors, so every row is an anchor and the features
    # are exactly permutation-equivariant; equal scores would otherwise be ranked by row index
    prev, curr, camera, _, inlier, R, t = hand_built_frame(np.random.default_rng(6), n=200, outliers=0.6)
    policy = load_sampler(ONE_SHOT)
    priors = policy.priors(prev, curr, camera)  # scores left out: unknown
    order = np.random.default_rng(0).permutation(200)
    np.testing.assert_allclose(policy.priors(prev[order], curr[order], camera, None), priors[order], atol=1e-5)
    assert priors[inlier].mean() > 5 * priors[~inlier].mean()  # geometry alone still tells them apart
    # the estimator samples from these very priors: the core given them draws the same and its
    # prior-aware stop (which reads the priors) stops at the same count
    mine = LearnedEstimator(ONE_SHOT).estimate(prev, curr, camera, None, rng=4)
    stop = {**DEFAULT_ESTIMATOR_OPTIONS, "confidence": 0.99, "first_batch_size": 4, "batch_size": 8}
    core = estimate_motion(prev, curr, camera, method="msac", priors=priors, rng=4, **stop)
    np.testing.assert_array_equal(mine.inliers, core.inliers)
    assert (mine.n_hypotheses, mine.n_point_checks) == (core.n_hypotheses, core.n_point_checks)
    assert pose_is_right(mine, R, t)


@pytest.mark.parametrize("sampler", [ONE_SHOT, IN_FRAME])
def test_scores_on_another_scale_are_refused_and_the_ends_of_0_1_taken(sampler):
    prev, curr, camera, scores, inlier, R, t = hand_built_frame(np.random.default_rng(8), outliers=0.3)
    estimator = LearnedEstimator(sampler)
    # a descriptor distance (lower = better, 0-255): the networks never saw such a score column
    distances = np.where(inlier, 20.0, 180.0)
    with pytest.raises(ValueError, match=r"scores must lie in \[0, 1\].* 300 of 300 outside, from 20 to 180"):
        estimator.estimate(prev, curr, camera, distances)
    one_off = scores.copy()
    one_off[7] = -1e-9
    with pytest.raises(ValueError, match=r"1 of 300 outside, from -1e-09 to"):
        estimator.estimate(prev, curr, camera, one_off)
    with pytest.raises(ValueError, match=r"scores must lie in \[0, 1\]"):
        load_sampler(ONE_SHOT).priors(prev, curr, camera, scores * 2.0)
    flags = inlier.astype(float)  # a matcher's 0 / 1 verdicts are scores at the ends of the range
    estimator.reset()
    assert pose_is_right(estimator.estimate(prev, curr, camera, flags), R, t)


@pytest.mark.parametrize("bad, match", [
    ("no-such-sampler", "unknown sampler 'no-such-sampler'"),
    ("missing/sampler.pt", "missing/sampler.pt"),
    ("README.md", "README.md"),
    (3, "sampler must be"),
])
def test_bad_samplers_get_one_line_naming_them(bad, match):
    with pytest.raises(ValueError, match=match) as info:
        LearnedEstimator(bad)
    assert "\n" not in str(info.value)


def test_bad_files_and_options_get_one_line(tmp_path):
    truncated = tmp_path / "truncated.pt"
    with importlib.resources.as_file(shipped_path(IN_FRAME)) as source:
        truncated.write_bytes(source.read_bytes()[:2000])
    folder = tmp_path / "folder.pt"
    folder.mkdir()
    foreign = tmp_path / "foreign.pt"
    torch.save({"weights": torch.zeros(3)}, foreign)
    for path in (truncated, folder, foreign):
        with pytest.raises(ValueError, match=str(path)) as info:
            LearnedEstimator(path)
        assert "\n" not in str(info.value)
    for kw, match in (({"budget": 0}, "budget"), ({"confidence": 1.0}, "confidence"),
                      ({"threshold_px": -1.0}, "threshold_px"), ({"method": "inlier-detection"}, "does not sample"),
                      ({"method": "nope"}, "nope"), ({"seed": "a"}, "seed must be .* got 'a'"),
                      ({"seed": -1}, "seed must be .* got -1"), ({"max_hypotheses": 32}, "max_hypotheses 32: caps an in-frame")):
        with pytest.raises(ValueError, match=match):
            LearnedEstimator(ONE_SHOT, **kw)
    # an option only the other kind uses is refused, not silently ignored
    with pytest.raises(ValueError, match="temperature 2.0: in-frame sampler 'adaptive-pg-prior'"):
        LearnedEstimator(IN_FRAME, temperature=2.0)
    with pytest.raises(ValueError, match="temperature 2.0: the loaded sampler"):
        LearnedEstimator(load_sampler(ONE_SHOT), temperature=2.0)
    prev, curr, camera, scores, *_ = hand_built_frame(np.random.default_rng(7), n=50)
    for sampler in (ONE_SHOT, IN_FRAME):
        with pytest.raises(ValueError, match="rng must be .* got 'abc'"):
            LearnedEstimator(sampler).estimate(prev, curr, camera, scores, rng="abc")


def test_a_shipped_sampler_through_the_api_beats_uniform_by_the_shipped_margin():
    # The frames of tests/agents/test_catalog.py (eps 0.8, N 500, three 10-frame episodes), and its margin.
    from tests.support.shipped import MARGIN, SEEDS, SETTING

    from vo_gym import StereoVOEnv

    frames = []
    for seed in SEEDS:
        env = StereoVOEnv(**SETTING)
        env.reset(seed=seed)
        frames.append([env.sequence.frame(k) for k in range(1, SETTING["n_frames"] + 1)])

    def rate(run) -> tuple[float, float]:
        rows = [(frame_metrics(e, f.truth).success, e.n_hypotheses) for episode in frames
                for f, e in zip(episode, run(episode))]
        return float(np.mean([s for s, _ in rows])), float(np.mean([h for _, h in rows]))

    def uniform(episode):
        return [estimate_motion(f.prev, f.curr, f.camera, method="msac", budget=16, rng=np.random.default_rng([7, f.index]),
                                **DEFAULT_ESTIMATOR_OPTIONS) for f in episode]

    def learned(estimator):
        return lambda episode: estimator.estimate_sequence([(f.prev, f.curr, f.camera, f.scores) for f in episode])

    floor, _ = rate(uniform)
    assert floor <= 0.4
    one_shot, _ = rate(learned(LearnedEstimator(ONE_SHOT, budget=16)))
    in_frame, hypotheses = rate(learned(LearnedEstimator(IN_FRAME)))
    assert one_shot >= floor + MARGIN, (one_shot, floor)
    assert in_frame >= floor + MARGIN and hypotheses <= 16, (in_frame, hypotheses, floor)
