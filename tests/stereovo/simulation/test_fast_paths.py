"""The simulator's faster paths give what their earlier formulations gave, bit for bit.

The candidate kernels stop at the rows the caller keeps (``limit``): their output is the first
rows of the full pass. The moving object's setup, on Python floats, equals the numpy formulation it
replaced (kept here as the reference). The fused noise-and-check kernel equals the two kernels,
and the validity mask the camera's two tests.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from stereovo.camera import StereoCamera
from stereovo.geometry import invert_transform, random_rotation
from stereovo.simulation import Sequence, SimulationConfig
from stereovo.simulation import outliers as outliers_module
from stereovo.simulation import pair as pair_module
from stereovo.simulation import world as world_module
from stereovo.simulation.world import CAMERA_HEIGHT, camera_vector


def _transforms(config: SimulationConfig, seed: int, k: int = 3) -> tuple[np.ndarray, np.ndarray]:
    poses = Sequence(config, seed).true_poses
    return invert_transform(poses[k - 1]) @ poses[k - 1], invert_transform(poses[k]) @ poses[k - 1]


@pytest.mark.parametrize("world", ["street", "open"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_landmark_kernels_stopped_at_a_limit_give_the_first_rows_of_the_full_pass(world, seed):
    config = SimulationConfig(world=world, preset="free" if world == "open" else "car")
    to_prev, to_curr = _transforms(config, seed)
    cam, n = config.camera, 900
    rng = np.random.default_rng(seed)
    if world == "street":
        layout = world_module._StreetLayout(rng)
        state = rng.bit_generator.state
        full = layout.sample_visible(rng, n, cam, config.z_min, config.z_max, to_prev, to_curr)
        after_full = rng.bit_generator.state
        for limit in (0, 1, 50, len(full[0]), n):
            rng.bit_generator.state = state
            part = layout.sample_visible(rng, n, cam, config.z_min, config.z_max, to_prev, to_curr, limit=limit)
            assert rng.bit_generator.state == after_full  # the whole batch is drawn either way
            for a, b in zip(part, full):
                np.testing.assert_array_equal(a, b[:limit])
    else:
        local = world_module._sample_open(rng, n, cam, config.z_min, config.z_max)
        args = (to_prev, to_curr, camera_vector(cam), config.z_min, config.z_max)
        full = world_module._seen_by_both(local, *args, n)
        assert 50 < len(full[0]) < n
        for limit in (0, 1, 50, len(full[0])):
            for a, b in zip(world_module._seen_by_both(local, *args, limit), full):
                np.testing.assert_array_equal(a, b[:limit])


def _reference_moving_object(n, config, to_prev, to_curr_static, rng):
    """:func:`stereovo.simulation.outliers.moving_object` as it was written before (numpy on 3-vectors,
    every candidate looked at)."""
    cam = config.camera
    cam_vector = camera_vector(cam)
    tau = outliers_module.outlier_threshold(config.noise_sigma)
    street = config.resolved_world == "street"
    z_lo, z_hi = max(5.0, config.z_min + 2.0), min(25.0, config.z_max - 2.0)
    if z_lo > z_hi:
        z_lo = z_hi = 0.5 * (config.z_min + config.z_max)
    for _ in range(30):
        depth = rng.uniform(z_lo, z_hi)
        centre = np.array([
            (rng.uniform(0.25, 0.75) * (cam.width - 1) - cam.cx) / cam.fx * depth,
            (rng.uniform(0.25, 0.75) * (cam.height - 1) - cam.cy) / cam.fy * depth,
            depth,
        ])
        if street:
            half = 0.5 * np.array([rng.uniform(1.6, 2.0), rng.uniform(1.4, 1.8), rng.uniform(3.5, 5.0)])
            centre[1] = CAMERA_HEIGHT - half[1]
            orientation = outliers_module._rotation_about_y(rng.uniform(-np.pi, np.pi))
            velocity = orientation[:, 2] * rng.uniform(0.5, 2.0) * (-1.0, 1.0)[int(rng.integers(0, 2))]
            spin = outliers_module._rotation_about_y(rng.uniform(-1, 1) * np.radians(3.0))
        else:
            half = 0.5 * rng.uniform(0.8, 3.0, 3)
            orientation = random_rotation(rng)
            direction = rng.standard_normal(3)
            velocity = direction / np.linalg.norm(direction) * rng.uniform(0.5, 2.0)
            spin = random_rotation(rng, np.radians(3.0))
        obj_R, obj_t = spin, centre - spin @ centre + velocity
        face_cdf = np.cumsum(np.array([half[1] * half[2], half[0] * half[2], half[0] * half[1]]))
        face_cdf /= face_cdf[-1]
        obj = np.eye(4)
        obj[:3, :3], obj[:3, 3] = obj_R, obj_t
        to_curr_moved = to_curr_static @ obj

        def draw(size):
            return outliers_module._object_candidates(
                rng.random((size, 5)), half, face_cdf, orientation, centre, to_prev, to_curr_moved,
                to_curr_static, cam_vector, config.z_min, config.z_max, tau, size,
            )

        probe = max(64, 2 * n)
        X_prev, X_curr = draw(probe)
        acceptance = len(X_prev) / probe
        if acceptance < 0.02:
            continue
        kept_prev, kept_curr, count = [X_prev], [X_curr], len(X_prev)
        while count < n:
            X_prev, X_curr = draw(int(1.3 * (n - count) / acceptance) + 32)
            kept_prev.append(X_prev)
            kept_curr.append(X_curr)
            count += len(X_prev)
        return np.concatenate(kept_prev)[:n], np.concatenate(kept_curr)[:n]
    raise AssertionError("no object placed")


@pytest.mark.parametrize("world,preset", [("street", "car"), ("open", "free"), ("open", "car")])
@pytest.mark.parametrize("n", [1, 2, 5, 50, 300])
def test_moving_object_equals_its_numpy_formulation(world, preset, n):
    config = SimulationConfig(world=world, preset=preset)
    for seed in range(6):
        to_prev, to_curr = _transforms(config, seed)
        ours_rng, reference_rng = np.random.default_rng(seed), np.random.default_rng(seed)
        ours = outliers_module.moving_object(n, config, to_prev, to_curr, ours_rng)
        reference = _reference_moving_object(n, config, to_prev, to_curr, reference_rng)
        for a, b in zip(ours, reference):
            assert a.shape == (n, 3)
            np.testing.assert_array_equal(a, b)
            assert np.array_equal(np.signbit(a), np.signbit(b))
        assert ours_rng.bit_generator.state == reference_rng.bit_generator.state


def test_the_spin_limit_is_three_degrees_as_numpy_converts_it():
    assert outliers_module._MAX_SPIN == np.radians(3.0) == math.radians(3.0)


@pytest.mark.parametrize("sigma", [0.5, 3.0, 40.0])
def test_fused_noise_and_check_equal_the_two_kernels(sigma):
    rng = np.random.default_rng(7)
    cam = SimulationConfig().camera
    meas = np.column_stack([rng.uniform(0, 1240, 400), rng.uniform(0, 375, 400), np.zeros(400), np.zeros(400)])
    meas[:, 2] = meas[:, 0] - rng.uniform(0.05, 60, 400)
    meas[:, 3] = meas[:, 1]
    z = rng.standard_normal((400, 3))
    limits = (float(cam.width - 1), float(cam.height - 1), float(cam.min_disparity))
    expected = np.empty((400, 4))
    pair_module._noisy_rows(meas, z, sigma, expected)
    out = np.empty((400, 4))
    bad = pair_module._noisy_invalid_rows(meas, z, sigma, out, *limits)
    np.testing.assert_array_equal(out, expected)
    np.testing.assert_array_equal(bad, np.flatnonzero(~pair_module._valid_rows(expected, *limits)))
    assert bad.dtype == np.int64 and bad.size > 0  # some rows start below the disparity floor


@pytest.mark.parametrize("entropy", [[2**62 + 5, 2**40, 2**33 + 7, 2**63 - 1], [0, 1, 2**32 - 1, 2**32], [5], [0]])
@pytest.mark.parametrize("n_children", [1, 5, 9])
def test_spawned_generators_are_numpys_spawned_children(entropy, n_children):
    from stereovo.seeding import spawned_generators

    ours = spawned_generators(np.array(entropy, dtype=np.int64), n_children)
    reference = [np.random.default_rng(s) for s in np.random.SeedSequence(entropy).spawn(n_children)]
    assert [a.bit_generator.state for a in ours] == [b.bit_generator.state for b in reference]


def test_spawned_generators_leave_other_entropy_to_numpy():
    from stereovo.seeding import spawned_generators

    assert spawned_generators(np.array([3, 4]), 0) == []
    (ours,) = spawned_generators(np.array([3, 2**40], dtype=np.uint64), 1)  # not int64: the general path
    assert ours.bit_generator.state == np.random.default_rng(np.random.SeedSequence([3, 2**40]).spawn(1)[0]).bit_generator.state
    with pytest.raises(ValueError, match="non-negative"):
        spawned_generators(np.array([3, -1], dtype=np.int64), 2)  # numpy's own error


def test_shuffled_rows_are_numpys_fancy_indexing():
    rng = np.random.default_rng(6)
    kinds, inlier = pair_module._row_kinds((7, 3, 2, 4, 0, 1, 0, 3))  # read-only, as a frame's
    n = kinds.shape[0]
    for _ in range(50):
        order = rng.permutation(n)
        prev, curr, scores = rng.standard_normal((n, 4)), rng.standard_normal((n, 4)), rng.random(n)
        prev[0, 1] = -0.0
        ours = pair_module._shuffled_rows(order, prev, curr, scores, inlier, kinds)
        for got, want in zip(ours, (prev[order], curr[order], scores[order], inlier[order], kinds[order])):
            assert got.dtype == want.dtype and got.shape == want.shape and got.tobytes() == want.tobytes()
            assert got.flags.c_contiguous and got.flags.writeable
    # other dtypes take numpy's indexing
    order = rng.permutation(n)
    ours = pair_module._shuffled_rows(order, prev.astype(np.float32), curr, scores, inlier, kinds)
    assert ours[0].dtype == np.float32 and ours[0].tobytes() == prev.astype(np.float32)[order].tobytes()


def test_camera_arrays_are_built_once_per_camera_and_read_only():
    config = SimulationConfig()
    a, b = camera_vector(config.camera), camera_vector(config.camera)
    assert a is b and not a.flags.writeable
    np.testing.assert_array_equal(a, [config.camera.fx, config.camera.fy, config.camera.cx, config.camera.cy,
                                      config.camera.baseline, config.camera.width, config.camera.height,
                                      config.camera.min_disparity])
    np.testing.assert_array_equal(world_module._frustum_vector(config.camera), world_module._frustum(config.camera))
    other = StereoCamera(fx=500.0, fy=500.0, cx=320.0, cy=240.0, baseline=0.3, width=640, height=480)
    assert camera_vector(other)[0] == 500.0 and world_module._frustum_vector(other)[1] == pytest.approx(1.15 * 319 / 500)


def test_frames_refuse_wrong_shapes_on_both_paths():
    from stereovo.simulation.frame import Frame

    frame = Sequence(SimulationConfig(n_frames=2), seed=0).frame(1)
    good = dict(index=1, prev=frame.prev, curr=frame.curr, scores=frame.scores, camera=frame.camera,
                noise_sigma=0.5, score_auc=0.75, truth=frame.truth)
    Frame(**good)
    Frame(**{**good, "prev": frame.prev.tolist()})  # lists: numpy's shape reading
    for bad in ({"prev": frame.prev[:, :3]}, {"curr": frame.curr[1:]}, {"scores": frame.scores[1:]},
                {"prev": frame.prev[0]}, {"scores": frame.scores[:, None]}):
        [(name, value)] = bad.items()  # the message names the field and the shape it got
        message = rf"Frame\.{name} .*must .*got .*{re.escape(str(np.shape(value)))}"
        with pytest.raises(ValueError, match=message):
            Frame(**{**good, **bad})
        with pytest.raises(ValueError, match=message):
            Frame(**{**good, **{k: np.asarray(v).tolist() for k, v in bad.items()}})


def test_validity_mask_is_the_cameras_in_image_and_has_depth():
    """The pair's compiled validity mask equals the camera's two tests on edge and random rows."""
    cam = StereoCamera()
    rng = np.random.default_rng(0)
    meas = np.column_stack([
        rng.uniform(-5, cam.width + 5, 4000), rng.uniform(-5, cam.height + 5, 4000),
        rng.uniform(-5, cam.width + 5, 4000), rng.uniform(-5, cam.height + 5, 4000),
    ])
    meas[:8] = [[0, 0, -1e-9, 0], [cam.width - 1, cam.height - 1, cam.width - 1 - cam.min_disparity, cam.height - 1],
                [cam.width - 1, 0, 0, 0], [10, 5, 10 - cam.min_disparity - 1e-9, 5], [np.nan, 1, 0, 1],
                [5, np.inf, 1, 1], [cam.width - 1 + 1e-9, 0, 3, 0], [7, 0, 3, cam.height - 1]]
    expected = cam.in_image(meas) & cam.has_depth(meas)
    np.testing.assert_array_equal(pair_module._valid(meas, cam), expected)
    assert 0 < expected.sum() < len(expected)


@pytest.mark.parametrize(
    "entropy",
    [[2**62 + 5, 2**40, 2**33 + 7, 2**63 - 1], [3, 2**40, 2**50, 2**60], [2**40, 0, 2**50, 2**32 - 1], [2**32] * 4],
)
def test_frame_streams_are_the_spawned_seed_sequences_of_the_entropy(entropy):
    """A frame's five streams are numpy's spawned children of its four entropy draws, small ints included."""
    ours = pair_module._stream_generators(np.array(entropy, dtype=np.int64), 5)
    reference = [np.random.default_rng(s) for s in np.random.SeedSequence(list(entropy)).spawn(5)]
    for a, b in zip(ours, reference):
        np.testing.assert_array_equal(a.integers(0, 2**62, 8), b.integers(0, 2**62, 8))
