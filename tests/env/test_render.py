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


def test_frames_carry_a_legend_of_the_marks_of_their_world():
    from sofar_env.env import SOfARRaceEnv
    from sofar_env.render import LEGEND, Renderer

    env = SOfARRaceEnv(render_mode="rgb_array", race={"duration": 2.0})
    env.reset(seed=0)
    for _ in range(5):
        env.step(np.array([0.5], np.float32))
    frame = env.render()
    left, top, right, bottom = env._renderer.legend_box
    assert (left, right, bottom) == (0, frame.shape[1], frame.shape[0]) and 0 < top < bottom  # a strip at the bottom
    panel = frame[top:bottom, left:right].reshape(-1, 3)
    drawn = {tuple(c) for c in np.unique(panel, axis=0).tolist()}
    absent = {"defending", "lifting", "sensed position"}  # the paper world: no defence, no lifts, no sensor
    for label, _, colour in LEGEND:
        assert (tuple(colour) in drawn) == (label not in absent), label  # in the colour the frame uses

    def draw(legend: bool, height: int = 480) -> np.ndarray:
        r = Renderer(env.track, env.config.race.vehicle, env.config.stack.mpc.barrier, height=height, legend=legend)
        return r.draw(env.race, env.last_output, gamma=0.5)

    np.testing.assert_array_equal(draw(True), frame)  # the env's frame is this renderer's
    # the legend covers no part of the view of the track: above it, the frame is a legend-free frame of that height
    np.testing.assert_array_equal(frame[:top], draw(False, height=top))
    assert Renderer(env.track, legend=False).legend_box is None
    env.close()


def test_the_legend_of_the_interactive_world_names_its_marks():
    from sofar_env.env import SOfARRaceEnv
    from sofar_env.render import LEGEND, legend_entries

    env = SOfARRaceEnv(scenario="interactive", render_mode="rgb_array", race={"duration": 1.0})
    env.reset(seed=0)
    env.render()
    assert legend_entries(env.race, seen=True) == LEGEND
    assert [e[0] for e in legend_entries(env.race, seen=False)] == [e[0] for e in LEGEND if e[0] != "sensed position"]
    env.close()


def test_animation_progress_bar(tmp_path, capsys):
    frames = [np.full((48, 64, 3), k, np.uint8) for k in (0, 80, 160)]
    write_animation(frames, tmp_path / "quiet.gif")
    assert "writing" not in capsys.readouterr().err
    write_animation(frames, tmp_path / "bar.gif", progress=True)
    assert "writing bar.gif" in capsys.readouterr().err


def test_gif_delta_frames_decode_to_the_frames(tmp_path):
    """Unchanged pixels are written as transparent: every decoded frame is still the frame given."""
    from PIL import Image

    frames = []
    for k in range(6):
        f = np.zeros((40, 60, 3), np.uint8)
        f[:, :, 1] = 90  # background
        f[5:15, 4 * k:4 * k + 10] = (230, 40, 40)  # a moving block
        f[25:35, 40:50] = (40, 110, 230) if k % 2 else (250, 250, 250)  # a block that changes colour
        frames.append(f)
    frames.append(frames[-1].copy())  # an unchanged frame
    path = write_animation(frames, tmp_path / "delta.gif")
    with Image.open(path) as gif:
        decoded = []
        for k in range(gif.n_frames):
            gif.seek(k)
            decoded.append(np.asarray(gif.convert("RGB")))
    for k, f in enumerate(frames[: len(decoded)]):
        np.testing.assert_array_equal(decoded[k], f, err_msg=f"frame {k}")
