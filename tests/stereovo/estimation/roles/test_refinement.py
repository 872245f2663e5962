"""The Levenberg-Marquardt / Gauss-Newton reprojection refiner (stereovo/estimation/roles/refinement.py):
Jacobians, normal equations, the compiled rounds."""

import numpy as np
import pytest

from stereovo.estimation.problem import StereoProblem
from stereovo.geometry import rotation_error, se3_exp
from tests.support.frames import CAMERA, noise_free_pair


def test_symmetric_reprojection_jacobian_matches_finite_differences():
    from stereovo.estimation.roles.reprojection import residuals_and_jacobians

    rng = np.random.default_rng(3)
    R_true, t_true = se3_exp(np.array([0.1, -0.05, 0.8, 0.02, -0.03, 0.01]))
    prev, curr = noise_free_pair(rng, R_true, t_true, n=20)
    problem = StereoProblem.build(prev, curr, CAMERA)
    R0, t0 = se3_exp(rng.normal(scale=0.02, size=6))
    R0, t0 = R0 @ R_true, R0 @ t_true + t0
    args = (problem.points_prev, problem.points_curr, problem.prev, problem.curr)
    res, jac = residuals_and_jacobians(CAMERA, R0[None], t0[None], *args)
    assert res.shape == (1, 20, 8) and jac.shape == (1, 20, 8, 6)
    numeric = np.empty_like(jac)
    h = 1e-6
    for k in range(6):
        step = np.zeros(6)
        step[k] = h
        dR_p, dt_p = se3_exp(step)
        dR_m, dt_m = se3_exp(-step)
        plus, _ = residuals_and_jacobians(CAMERA, (dR_p @ R0)[None], (dR_p @ t0 + dt_p)[None], *args, with_jacobian=False)
        minus, _ = residuals_and_jacobians(CAMERA, (dR_m @ R0)[None], (dR_m @ t0 + dt_m)[None], *args, with_jacobian=False)
        numeric[..., k] = (plus - minus) / (2 * h)
    np.testing.assert_allclose(jac, numeric, rtol=1e-4, atol=1e-3)


@pytest.mark.parametrize("huber", [None, 2.0])
def test_gauss_newton_step_solves_the_normal_equations_of_the_jacobian_rows(huber):
    # The LM kernel sums J^T W J from each side's 3x3 terms rather than the 8 x 6 rows: one
    # plain Gauss-Newton step must equal the step computed here from the rows themselves.
    from stereovo.estimation.roles.reprojection import gauss_newton_steps, residuals_and_jacobians

    rng = np.random.default_rng(8)
    R_true, t_true = se3_exp(np.array([0.3, -0.1, 1.2, 0.03, -0.02, 0.05]))
    prev, curr = noise_free_pair(rng, R_true, t_true, n=60)
    curr = curr + rng.normal(0, 1.0, curr.shape)
    problem = StereoProblem.build(prev, curr, CAMERA)
    dR, dt = se3_exp(rng.normal(scale=0.01, size=6))
    R0, t0 = dR @ R_true, dR @ t_true + dt
    weights = rng.uniform(0.2, 1.0, 60) * (rng.random(60) > 0.3)
    args = (problem.points_prev, problem.points_curr, problem.prev, problem.curr)
    res, jac = residuals_and_jacobians(CAMERA, R0[None], t0[None], *args)
    res, jac = res[0], jac[0]
    w = weights.copy()
    if huber is not None:
        norm = np.linalg.norm(res, axis=1)
        w[norm > huber] *= huber / norm[norm > huber]
    A = np.einsum("m,mri,mrj->ij", w, jac, jac)
    g = np.einsum("m,mri,mr->i", w, jac, res)
    delta = -np.linalg.solve(A + 1e-9 * np.diag(np.diag(A)), g)
    dR_ref, dt_ref = se3_exp(delta)
    R, t, _ = gauss_newton_steps(
        CAMERA, R0[None], t0[None], *args, weights=weights, iterations=1, damping=1e-9, huber=huber, step_control=False
    )
    np.testing.assert_allclose(R[0], dR_ref @ R0, atol=1e-12)
    np.testing.assert_allclose(t[0], dR_ref @ t0 + dt_ref, atol=1e-10)

def test_gauss_newton_refinement_reaches_the_noise_free_motion():
    from stereovo.estimation.roles.reprojection import gauss_newton_steps

    rng = np.random.default_rng(4)
    R_true, t_true = se3_exp(np.array([-0.2, 0.05, 1.1, 0.01, 0.04, -0.02]))
    prev, curr = noise_free_pair(rng, R_true, t_true, n=60)
    problem = StereoProblem.build(prev, curr, CAMERA)
    dR, dt = se3_exp(np.array([0.05, -0.05, 0.1, 0.01, -0.01, 0.02]))
    R, t, cost = gauss_newton_steps(
        CAMERA, (dR @ R_true)[None], (dR @ t_true + dt)[None],
        problem.points_prev, problem.points_curr, problem.prev, problem.curr, iterations=20,
    )
    assert rotation_error(R[0], R_true) < 1e-9
    assert np.linalg.norm(t[0] - t_true) < 1e-9
    assert cost[0] < 1e-12


@pytest.mark.parametrize("gate", [None, "pixel"])
def test_refinement_returns_the_residuals_that_selected_its_inliers(gate):
    from stereovo.estimation.roles.refinement import ReprojectionRefiner
    from stereovo.estimation.roles.scoring import PixelMahalanobisResidual, ReprojectionResidual
    from stereovo.simulation import SimulationConfig, simulate_frame

    frame = simulate_frame(SimulationConfig(n_correspondences=300, outlier_ratio=0.4), np.random.default_rng(5))
    problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
    model, threshold = ReprojectionResidual(), 9.0
    refiner = ReprojectionRefiner(iterations=3, rounds=2)
    if gate == "pixel":
        refiner = ReprojectionRefiner(iterations=3, rounds=2, gate=(PixelMahalanobisResidual(), 13.28))
        model_used, threshold_used = refiner.gate
    else:
        model_used, threshold_used = model, threshold
    R0, t0 = frame.truth.rotation @ se3_exp(np.full(6, 3e-4))[0], frame.truth.translation + 0.002
    start = model.squared(problem, R0[None], t0[None])[0] < threshold
    R, t, inliers, residual_sq = refiner.refine_with_residuals(problem, R0, t0, start, model, threshold)
    np.testing.assert_array_equal(inliers, model_used.squared(problem, R[None], t[None])[0] < threshold_used)
    if gate is None:  # the caller's own model: residuals come back for it to score with
        np.testing.assert_array_equal(residual_sq, model.squared(problem, R[None], t[None])[0])
    else:  # inliers chosen by the refiner's own gate: the caller's model was never evaluated
        assert residual_sq is None
    assert rotation_error(R, frame.truth.rotation) < rotation_error(R0, frame.truth.rotation)
    plain = refiner.refine(problem, R0, t0, start, model, threshold)
    for a, b in zip(plain, (R, t, inliers)):
        np.testing.assert_array_equal(a, b)
    # Too few inliers to refit: the motion comes back as given, with no residuals of it.
    few = np.zeros(problem.n, dtype=bool)
    few[:2] = True
    R2, t2, _, none = ReprojectionRefiner(rounds=2).refine_with_residuals(problem, R0, t0, few, model, threshold)
    assert none is None and np.array_equal(R2, R0) and np.array_equal(t2, t0)


@pytest.mark.parametrize("gate_kind", ["reprojection", "mahalanobis", "pixel-gate", "huber"])
def test_compiled_refinement_rounds_equal_the_python_loop(gate_kind):
    """The compiled loop must reproduce the Python loop bit for bit (poses, inliers, residuals)."""
    from stereovo.estimation.roles.refinement import ReprojectionRefiner
    from stereovo.estimation.roles.scoring import (
        MahalanobisResidual,
        PixelMahalanobisResidual,
        ReprojectionResidual,
    )
    from stereovo.simulation import SimulationConfig, simulate_frame

    model, threshold = (MahalanobisResidual(), 7.81) if gate_kind == "mahalanobis" else (ReprojectionResidual(), 9.0)
    gate = (PixelMahalanobisResidual(), 13.28) if gate_kind == "pixel-gate" else None
    refiner = ReprojectionRefiner(iterations=6, rounds=3, gate=gate, huber_px=1.0 if gate_kind == "huber" else None)
    for seed in range(4):
        frame = simulate_frame(SimulationConfig(n_correspondences=250, outlier_ratio=0.5), np.random.default_rng(seed))
        problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
        R0 = frame.truth.rotation @ se3_exp(np.full(6, 2e-4 * (seed + 1)))[0]
        t0 = frame.truth.translation + 0.002 * seed
        start = model.squared(problem, R0[None], t0[None])[0] < threshold
        compiled = refiner._refine_compiled(problem, R0, t0, start, model, threshold)
        python = refiner._refine_in_python(problem, R0, t0, start, model, threshold)
        assert compiled[3] is not None
        for a, b in zip(compiled, python):
            np.testing.assert_array_equal(a, b)
        assert compiled[2].sum() > 0.9 * start.sum()


@pytest.mark.parametrize("compiled", [True, False])
def test_start_residuals_and_gate_residuals_are_the_ones_computed(compiled):
    """``start_sq`` (the gate's residuals of the starting motion, which the final report has) and
    ``gate_residuals`` (those of the returned motion under the gate that chose its inliers) change
    nothing but what is computed: the same fit, and the residuals the gate gives it."""
    from stereovo.estimation.roles.refinement import ReprojectionRefiner
    from stereovo.estimation.roles.scoring import MahalanobisResidual, PixelMahalanobisResidual, ReprojectionResidual
    from stereovo.simulation import SimulationConfig, simulate_frame

    gate = PixelMahalanobisResidual(13.28) if compiled else _UncompiledPixelGate(13.28)
    refiner = ReprojectionRefiner(iterations=6, rounds=3, gate=(gate, 13.28))
    model, threshold = MahalanobisResidual(), 7.81
    for seed in range(3):
        frame = simulate_frame(SimulationConfig(n_correspondences=250, outlier_ratio=0.5), np.random.default_rng(seed))
        problem = StereoProblem.build(frame.prev, frame.curr, frame.camera, frame.noise_sigma)
        R0 = frame.truth.rotation @ se3_exp(np.full(6, 3e-4 * (seed + 1)))[0]
        t0 = frame.truth.translation + 0.003 * seed
        start = model.squared(problem, R0[None], t0[None])[0] < threshold
        plain = refiner.refine_with_residuals(problem, R0, t0, start, model, threshold)
        start_sq = gate.squared(problem, R0[None], t0[None])[0]
        given = refiner.refine_with_residuals(problem, R0, t0, start, model, threshold, start_sq=start_sq,
                                              gate_residuals=True)
        for a, b in zip(plain[:3], given[:3]):
            np.testing.assert_array_equal(a, b)
        assert plain[3] is None  # the caller's model was never evaluated
        np.testing.assert_array_equal(given[3], gate.squared(problem, given[0][None], given[1][None])[0])
        np.testing.assert_array_equal(given[2], given[3] < 13.28)
        # start residuals that are not the start motion's show they are read: another selection
        shifted = refiner.refine_with_residuals(problem, R0, t0, start, model, threshold,
                                                start_sq=np.where(start_sq < 13.28, 1e9, 0.0))
        assert not np.array_equal(shifted[2], plain[2])
    unused = ReprojectionRefiner(iterations=3, rounds=2)  # no gate of its own: start_sq has no role
    a = unused.refine_with_residuals(problem, R0, t0, start, ReprojectionResidual(), 9.0)
    b = unused.refine_with_residuals(problem, R0, t0, start, ReprojectionResidual(), 9.0, start_sq=np.zeros(problem.n))
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x, y)


class _UncompiledPixelGate:
    """The pixel gate under another class: the refiner runs its Python rounds for it."""

    def __init__(self, threshold_sq):
        from stereovo.estimation.roles.scoring import PixelMahalanobisResidual

        self.inner = PixelMahalanobisResidual(threshold_sq)

    def squared(self, problem, R, t, cap=None):
        return self.inner.squared(problem, R, t)
