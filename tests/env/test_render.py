"""Rendering: rgb_array frames, animation files, RecordVideo when moviepy is available."""


import gymnasium as gym
import numpy as np
import pytest

import sofar_env  # noqa: F401
from sofar_env.render import write_animation


def test_rgb_array_frames():
    env = gym.make("SOfAR-LagunaSeca-v0", render_mode="rgb_array", config={"race": {"duration": 1.0}})
    env.reset(seed=0)
    first = env.render()
    for _ in range(3):
        env.step(np.array([0.5], np.float32))
    frame = env.render()
    assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
    assert frame.shape == first.shape
    assert len(np.unique(frame.reshape(-1, 3), axis=0)) > 5  # track, cars, text: not a blank image
    assert not np.array_equal(frame, first)  # the camera follows the ego
    env.close()


def test_render_without_mode_returns_none():
    env = gym.make("SOfAR-LagunaSeca-v0", config={"race": {"duration": 1.0}})
    env.reset(seed=0)
    with pytest.warns(UserWarning):
        assert env.render() is None
    env.close()


def test_frames_written_to_an_animation(tmp_path):
    """The frame writer of the demo (RecordVideo needs moviepy, which the project does not install)."""
    env = gym.wrappers.RenderCollection(
        gym.make("SOfAR-LagunaSeca-v0", render_mode="rgb_array", config={"race": {"duration": 0.5}}))
    env.reset(seed=0)
    done = False
    while not done:
        _, _, terminated, truncated, _ = env.step(np.array([0.5], np.float32))
        done = terminated or truncated
    frames = env.render()
    assert len(frames) == 6  # the reset frame + 5 steps
    path = write_animation(frames, tmp_path / "race.gif", fps=10)
    from PIL import Image

    with Image.open(path) as gif:
        assert gif.n_frames == 6 and gif.size == (frames[0].shape[1], frames[0].shape[0])
    env.close()


def test_record_video(tmp_path):
    env = gym.wrappers.RecordVideo(
        gym.make("SOfAR-LagunaSeca-v0", render_mode="rgb_array", config={"race": {"duration": 0.5}}),
        str(tmp_path), episode_trigger=lambda ep: True, disable_logger=True)
    env.reset(seed=0)
    done = False
    while not done:
        _, _, terminated, truncated, _ = env.step(np.array([0.5], np.float32))
        done = terminated or truncated
    env.close()
    assert list(tmp_path.glob("*.mp4"))


def test_human_mode_draws_into_a_matplotlib_figure():
    import matplotlib

    matplotlib.use("Agg", force=True)  # no display in tests
    env = gym.make("SOfAR-LagunaSeca-v0", render_mode="human", config={"race": {"duration": 0.3}})
    env.reset(seed=0)
    env.step(np.array([0.5], np.float32))
    renderer = env.unwrapped._renderer
    assert renderer is not None and renderer._figure is not None
    image = renderer._image.get_array()
    assert image.shape[2] == 3 and image.dtype == np.uint8
    env.close()
    assert env.unwrapped._renderer is None
