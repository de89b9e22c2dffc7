"""``SOfAR-Custom-v0``: a circuit of your own by folder path or Track, and clear errors for a bad ``track``."""

from __future__ import annotations

import shutil

import gymnasium as gym
import numpy as np
import pytest

import sofar_env  # noqa: F401  (registers the ids)
from sofar_env.registration import CUSTOM_ID
from sofar_env.tracks import Track, TrackFormatError, build_track

SHORT = {"duration": 1.0}


def _write_centerline(path, n: int = 400) -> None:
    """A closed, smooth circuit of about 1.9 km with a 12 m wide track (x_m, y_m, w_tr_right_m, w_tr_left_m)."""
    t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    rows = np.column_stack([400.0 * np.cos(t), 180.0 * np.sin(t) + 30.0 * np.sin(2.0 * t),
                            np.full(n, 6.0), np.full(n, 6.0)])
    np.savetxt(path, rows, delimiter=",", header="x_m,y_m,w_tr_right_m,w_tr_left_m", comments="", fmt="%.4f")


@pytest.fixture(scope="module")
def oval(tmp_path_factory):
    """(folder, in-memory Track) of the same circuit built by the builder."""
    tmp = tmp_path_factory.mktemp("custom")
    csv = tmp / "oval.csv"
    _write_centerline(csv)
    build_track(csv, "Oval", tmp / "Oval", source_format="centerline")
    return tmp / "Oval", build_track(csv, "Oval", source_format="centerline")


def _rollout(env, steps: int = 5) -> np.ndarray:
    obs, _ = env.reset(seed=3)
    rows = [obs]
    for _ in range(steps):
        obs, *_ = env.step(np.array([0.4], np.float32))
        rows.append(obs)
    env.close()
    return np.array(rows)


@pytest.mark.parametrize("how", ["str", "Path", "config"])
def test_custom_id_races_on_a_built_folder(oval, how):
    folder, _ = oval
    kwargs = {"str": {"track": str(folder), "race": SHORT}, "Path": {"track": folder, "race": SHORT},
              "config": {"config": {"track": str(folder), "race": SHORT}}}[how]
    env = gym.make(CUSTOM_ID, **kwargs)
    track = env.unwrapped.config.track
    assert isinstance(track, Track) and track.name == "Oval"  # loaded (and checked) when the env is made
    obs, _ = env.reset(seed=0)
    assert env.unwrapped.track is track
    _, reward, terminated, _, info = env.step(np.array([0.5], np.float32))
    assert env.observation_space.contains(obs) and isinstance(reward, float) and not terminated
    assert 0.0 < info["laps"] < 0.1
    env.close()


def test_custom_id_takes_a_track_object_as_is_and_matches_the_folder(oval):
    folder, _ = oval
    track = Track.load(folder)
    env = gym.make(CUSTOM_ID, track=track, race=SHORT)
    assert env.unwrapped.config.track is track
    from_object = _rollout(env)
    assert env.unwrapped.track is track
    from_folder = _rollout(gym.make(CUSTOM_ID, track=folder, race=SHORT))
    np.testing.assert_array_equal(from_object, from_folder)  # same circuit, same seed: same trajectory


def test_custom_id_races_on_an_in_memory_track_of_the_builder(oval):
    folder, built = oval
    from_memory = _rollout(gym.make(CUSTOM_ID, track=built, race=SHORT))
    from_folder = _rollout(gym.make(CUSTOM_ID, track=folder, race=SHORT))
    # the folder stores the arrays with 12 significant digits: the same race up to that rounding
    np.testing.assert_allclose(from_memory, from_folder, atol=1e-4)


def test_custom_id_in_vector_mode_and_the_interactive_world(oval):
    folder, _ = oval
    env = gym.make(CUSTOM_ID, track=folder, scenario="interactive", reward_mode="vector", race=SHORT)
    assert env.unwrapped.config.scenario == "interactive"
    env.reset(seed=0)
    _, reward, *_ = env.step(np.array([0.5], np.float32))
    assert reward.shape == (5,)
    env.close()


@pytest.mark.parametrize("kwargs, match", [
    ({}, "SOfAR-Custom-v0 needs track="),
    ({"track": None}, "SOfAR-Custom-v0 needs track="),
    ({"track": 7}, "track must be a circuit folder path or a Track, got int"),
    ({"track": "Monza"}, "'Monza' is not a circuit folder.*SOfAR-<Circuit>-v0"),
    ({"track": "no/such/folder"}, "'no/such/folder' is not a circuit folder.*python -m sofar_env.tracks build"),
])
def test_missing_or_wrong_track_is_a_clear_error(kwargs, match):
    with pytest.raises(ValueError, match=match):
        gym.make(CUSTOM_ID, **kwargs)


@pytest.mark.parametrize("damage, named", [("raceline.csv", "raceline.csv"), ("meta.json", "meta.json")])
def test_malformed_folder_names_the_file(oval, tmp_path, damage, named):
    folder, _ = oval
    broken = tmp_path / "Broken"
    shutil.copytree(folder, broken)
    if damage == "meta.json":
        (broken / damage).unlink()
    else:
        (broken / damage).write_text("s_m,x_m\n0,1\n")
    with pytest.raises(TrackFormatError, match=named):
        gym.make(CUSTOM_ID, track=broken)


def test_shipped_ids_accept_a_track_object_too():
    monza = Track.load("Monza")
    env = gym.make("SOfAR-LagunaSeca-v0", track=monza, race=SHORT)
    env.reset(seed=0)
    env.step(np.array([0.5], np.float32))
    assert env.unwrapped.track is monza
    env.close()
