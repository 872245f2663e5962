"""``vo_gym/StereoVOImages-v0``: Gymnasium's checkers, the observation layout of StereoVO-v0,
same seed same episode, shipped samplers on it, a recorded source, and its argument errors."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from tests.support.images import rendered, write_kitti

pytest.importorskip("cv2", reason="the image front end needs OpenCV: pip install 'vo-gym[images]'")
pytest.importorskip("moderngl", reason="rendered sequences need moderngl: pip install 'vo-gym[render]'")

import vo_gym  # noqa: E402,F401
from stereovo.estimation import StereoProblem  # noqa: E402
from vo_gym.features import FEATURE_NAMES, N_FEATURES  # noqa: E402
from vo_gym.images_env import StereoVOImagesEnv  # noqa: E402

SMALL = dict(n_frames=2, resolution="vga", max_correspondences=600)


@pytest.fixture(scope="module", autouse=True)
def egl():
    sequence = rendered(n_frames=1, resolution="vga")  # skips loudly where EGL is missing
    sequence.close()


def test_gymnasiums_checkers_pass():
    env = StereoVOImagesEnv(**SMALL)
    check_env(env, skip_render_check=True)
    env.close()
    made = gym.make("vo_gym/StereoVOImages-v0", **SMALL)  # wrapped in the passive checker
    obs, info = made.reset(seed=3)
    assert made.observation_space.contains(obs)
    obs, reward, terminated, truncated, info = made.step(made.action_space.sample())
    assert made.observation_space.contains(obs) and -1.0 <= reward <= 1.0 and not terminated
    made.close()


def test_the_observation_layout_is_the_simulated_environments():
    images = StereoVOImagesEnv(**SMALL)
    simulated = gym.make("vo_gym/StereoVO-v0", n_correspondences=600).unwrapped
    assert images.observation_space["features"].shape == (600, N_FEATURES)
    assert images.feature_names == simulated.feature_names == FEATURE_NAMES
    assert images.feature_layout_version == simulated.feature_layout_version
    assert images.observation_space == simulated.observation_space
    assert images.action_space == simulated.action_space
    obs, _ = images.reset(seed=0)
    frame = images.current_frame
    # the rows with a resolvable depth (the estimator's rule), none past the frame's own rows
    usable = StereoProblem.build(frame.prev, frame.curr, frame.camera, images.estimator_noise_sigma).usable_mask
    np.testing.assert_array_equal(obs["mask"][: frame.n], usable)
    assert usable.mean() > 0.9 and not obs["mask"][frame.n:].any()
    assert not obs["features"][frame.n:].any()
    images.close()


def _episode(env, seed, actions):
    obs, info = env.reset(seed=seed)
    out = [(obs["features"].copy(), obs["mask"].copy(), info)]
    done = False
    i = 0
    while not done:
        obs, reward, terminated, truncated, info = env.step(actions[i])
        out.append((obs["features"].copy(), obs["mask"].copy(), reward, info))
        done = terminated or truncated
        i += 1
    return out


def _same(a, b):
    assert len(a) == len(b)
    for x, y in zip(a, b):
        assert np.array_equal(x[0], y[0]) and np.array_equal(x[1], y[1])
        assert x[2:] == y[2:]


def test_same_seed_same_episode_in_a_fresh_environment_and_from_the_cache():
    actions = np.random.default_rng(0).uniform(-3, 3, (2, 600)).astype(np.float32)
    first, second = StereoVOImagesEnv(**SMALL), StereoVOImagesEnv(**SMALL)
    a = _episode(first, 7, actions)
    _same(a, _episode(second, 7, actions))
    _same(a, _episode(first, 7, actions))  # the cached frames of seed 7
    other = _episode(first, 8, actions)
    assert not np.array_equal(a[0][0], other[0][0])
    assert a[-1][-1]["trajectory"]["success_rate"] == 1.0
    first.close()
    second.close()


def test_a_shipped_sampler_runs_on_it_unchanged():
    pytest.importorskip("torch", reason="the learned samplers need torch: pip install 'vo-gym[train]'")
    from agents.checkpoint import load_sampler

    policy = load_sampler("ngransac-supervised")
    env = StereoVOImagesEnv(**SMALL)
    obs, _ = env.reset(seed=1)
    logits = np.asarray(policy.act(obs), dtype=np.float32)
    assert logits.shape == (600,)
    obs, reward, terminated, truncated, info = env.step(np.clip(logits, -10, 10))
    assert info["success"] and reward > 0.5
    env.close()


def test_a_recorded_source_gives_windows_placed_by_the_seed(tmp_path):
    from stereovo.sequences import KittiOdometry

    source_frames = rendered(n_frames=5, resolution="vga", seed=2)
    write_kitti(tmp_path, source_frames, "03")
    source = KittiOdometry(tmp_path, "03")
    env = StereoVOImagesEnv(source=source, n_frames=2, max_correspondences=600)
    offsets = set()
    for seed in range(6):
        env.reset(seed=seed)
        offsets.add(env.sequence.offset)
        assert np.allclose(env.true_poses[0], source.true_poses[env.sequence.offset])
    assert len(offsets) > 1 and offsets <= {0, 1, 2}
    obs, reward, terminated, truncated, info = env.step(np.zeros(600, np.float32))
    assert info["success"]
    env.close()
    source_frames.close()


@pytest.mark.parametrize("kwargs, error, message", [
    ({"n_correspondences": 100}, TypeError, "are simulator settings"),
    ({"outliers": "hostile"}, TypeError, "['outliers'] are simulator settings"),
    ({"noise_dof": 3.0}, TypeError, "['noise_dof'] are simulator settings"),
    ({"max_correspondences": 2}, ValueError, "StereoVOImagesEnv: max_correspondences must be an integer >= 3"),
    ({"resolution": "hd"}, ValueError, "StereoVOImagesEnv: resolution must be one of 'kitti', 'vga', got 'hd'"),
    ({"frontend_options": {"detector": "surf"}}, ValueError, "FrontendOptions.detector must be one of"),
    ({"frontend_options": {"colour": True}}, TypeError, "StereoVOImagesEnv: frontend_options"),
    ({"source": 5}, ValueError, "source must be a frame sequence with known poses"),
    ({"method": "nope"}, ValueError, "StereoVOImagesEnv: method"),
])
def test_bad_arguments_are_named(kwargs, error, message):
    with pytest.raises(error) as err:
        StereoVOImagesEnv(**{**SMALL, **kwargs})
    assert message in str(err.value)


def test_frames_beyond_the_rows_keep_their_best_scored_matches():
    wide = StereoVOImagesEnv(n_frames=1, resolution="vga", max_correspondences=1000)
    narrow = StereoVOImagesEnv(n_frames=1, resolution="vga", max_correspondences=50)
    wide.reset(seed=4)
    obs, _ = narrow.reset(seed=4)
    full, cut = wide.current_frame, narrow.current_frame
    assert full.n > 50 and cut.n == 50 and obs["mask"].sum() <= 50
    best = np.sort(np.argsort(-full.scores, kind="stable")[:50])
    assert np.array_equal(cut.prev, full.prev[best]) and np.array_equal(cut.truth.inlier, full.truth.inlier[best])
    wide.close()
    narrow.close()


def _replayed(n_frames: int = 3):
    """Simulated frames served as a source: a sequence object that is no rendered world."""
    from stereovo.simulation import Sequence, SimulationConfig
    from vo_gym.images_env import ReplayedFrames

    sequence = Sequence(SimulationConfig(n_frames=n_frames, n_correspondences=100), 0)
    frames = [sequence.frame(k) for k in range(1, n_frames + 1)]
    return ReplayedFrames(frames, frames[0].camera, sequence.true_poses[: n_frames + 1], 0.5)


def test_a_source_refuses_the_rendered_worlds_arguments_it_would_ignore():
    vga = rendered(n_frames=1, resolution="vga")
    with pytest.raises(ValueError) as err:
        StereoVOImagesEnv(source=vga, resolution="kitti", preset="free", moving_objects=3)
    assert str(err.value) == ("StereoVOImagesEnv: preset='free', resolution='kitti', moving_objects=3 would be "
                              "ignored: they set the world rendered when source is None, and source=RenderedSequence "
                              "brings its own frames and camera; leave them out")
    vga.close()
    # even where they agree with the source, and with a source string (refused before it is opened)
    for source, kwargs, named in ((_replayed(), {"image_noise": 2.0}, "image_noise=2.0"),
                                  (_replayed(), {"texture_seed": None}, "texture_seed=None"),
                                  ("rendered", {"speed": 1.0, "world": "open"}, "speed=1.0, world='open'")):
        with pytest.raises(ValueError, match=f"^StereoVOImagesEnv: {named} would be ignored"):
            StereoVOImagesEnv(source=source, n_frames=2, **kwargs)
    with pytest.raises(ValueError, match=r"^StereoVOImagesEnv: frontend_options=\{'n_features': 500\} would be "
                                         r"ignored: source=ReplayedFrames matched its frames with its own front end"):
        StereoVOImagesEnv(source=_replayed(), n_frames=2, frontend_options={"n_features": 500})
    source = _replayed()
    env = StereoVOImagesEnv(source=source, n_frames=2, max_correspondences=100)  # nothing of a world given
    env.reset(seed=0)
    assert env.current_frame.camera is source.camera


def test_gymnasium_tools_render_it_or_pass_render_mode_none():
    source = _replayed()
    plain = gym.make("vo_gym/StereoVOImages-v0", source=source, n_frames=2, max_correspondences=100, render_mode=None)
    assert plain.unwrapped.render_mode is None
    env = gym.make("vo_gym/StereoVOImages-v0", source=source, n_frames=2, max_correspondences=100,
                   render_mode="rgb_array")
    assert env.metadata["render_modes"] == ["rgb_array"]
    env.reset(seed=0)
    env.step(np.zeros(100, np.float32))
    image = env.render()
    assert image.ndim == 3 and image.shape[2] == 3 and image.dtype == np.uint8 and image.std() > 0


@pytest.mark.parametrize("kwargs", [{}, {"sampling": "prosac"}, {"reward_mode": "msac"},
                                    {"render_mode": "rgb_array"}])
def test_a_frame_without_matches_is_a_failed_frame(tmp_path, kwargs):
    """Blank images give a frame of no matches: a failed frame (success False, the failure reward, the
    constant-velocity fallback), as a frame of too few matches is; the guided priors' maximum of no
    logits raised numpy's "zero-size array" error from the step."""
    import warnings

    from tests.support.images import write_image_folder

    folder = write_image_folder(tmp_path / "blank", blank=True, poses=True)
    env = gym.make("vo_gym/StereoVOImages-v0", source=f"kitti:{folder}", n_frames=1, max_correspondences=100,
                   **kwargs)
    obs, _ = env.reset(seed=0)
    assert env.unwrapped.current_frame.n == 0 and not obs["mask"].any()
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # (the rendering's weights divided 0 by 0)
        obs, reward, terminated, truncated, info = env.step(np.zeros(100, np.float32))
        assert reward == -1.0 and not info["success"] and info["fallback"] and not terminated and truncated
        assert info["status"] == "failed: too few correspondences (0, need 6)"
        assert info["trajectory"]["failed_frames"] == 1
        if "render_mode" in kwargs:
            assert env.render().shape[2] == 3
    env.close()


def test_images_too_small_for_features_are_refused_naming_their_size(tmp_path):
    """2x2 images were refused as 'invalid simulator setting: SimulationConfig.z_max ...', a setting
    the user never gave: the loader refuses them, naming the image and its size."""
    from tests.support.images import write_image_folder

    folder = write_image_folder(tmp_path / "tiny", width=2, height=2, poses=True)
    with pytest.raises(ValueError, match=r"tiny/image_0/000000.png is a 2x2 image; the front end finds no features") \
            as err:
        gym.make("vo_gym/StereoVOImages-v0", source=f"kitti:{folder}", n_frames=1, max_correspondences=100)
    assert "z_max" not in str(err.value)


ASYNC_AFTER_RENDERING = '''
import multiprocessing
import gymnasium as gym
import vo_gym
from stereovo.sequences import rendering

SMALL = dict(n_frames=2, resolution="vga", max_correspondences=60)


def vector_reset(context):
    vec = gym.make_vec("vo_gym/StereoVOImages-v0", num_envs=2, vectorization_mode="async",
                       vector_kwargs={"context": context}, **SMALL)
    vec.reset_async(seed=[3, 4])
    try:
        obs, _ = vec.reset_wait(timeout=90)
        return f"reset {obs['features'].shape}"
    except rendering.RenderingUnavailable as err:
        return f"refused: {err}"
    except multiprocessing.TimeoutError:
        return "hung"
    finally:
        vec.close(terminate=True)


if __name__ == "__main__":
    print(rendering.__file__)
    env = gym.make("vo_gym/StereoVOImages-v0", **SMALL)
    env.reset(seed=0)  # this process renders (and has closed its env)
    env.close()
    print(vector_reset("fork"))
    print(vector_reset("forkserver"))
'''


def test_async_vector_env_forked_after_rendering_is_refused_naming_forkserver_which_works(tmp_path):
    """Forked async workers of a process that had rendered hung in Mesa (llvmpipe's threads do not
    survive fork); their reset now raises RenderingUnavailable naming the forkserver context, and
    with that context the same reset works. In a fresh interpreter that bounds the wait."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    script = tmp_path / "async_after_rendering.py"  # a file: forkserver workers import the main module
    script.write_text(ASYNC_AFTER_RENDERING)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(root), *filter(None, [os.environ.get("PYTHONPATH")])])}
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=400, env=env)
    assert out.returncode == 0, out.stderr
    module, forked, forkserver = out.stdout.splitlines()
    assert Path(module).is_relative_to(root)  # this checkout's code ran
    assert forked.startswith("refused: this process was forked from one that had made an OpenGL context")
    assert "vector_kwargs={'context': 'forkserver'}" in forked
    assert forkserver.startswith("reset (2, 60, ")  # both workers rendered their episodes
