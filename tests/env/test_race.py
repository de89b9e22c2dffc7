"""The race world: overtakes and respawn, collisions, off-track, determinism, laps."""

from dataclasses import replace

import numpy as np
import pytest

from sofar_env.opponents import OpponentConfig
from sofar_env.race import Race, RaceConfig
from sofar_env.tracks import Track

ZERO = np.zeros((1, 2))


@pytest.fixture(scope="module")
def track():
    return Track.load("LagunaSeca")


def straightest(track, span=60.0, need_left=0.0):
    """Arc length where the raceline is straightest over ``span`` m (and the left width exceeds ``need_left``)."""
    best, best_k = None, np.inf
    for s0 in np.arange(0.0, track.length, 10.0):
        s = s0 + np.arange(0.0, span, 2.0)
        if np.min(track.width_left(s)) < need_left:
            continue
        k = float(np.max(np.abs(track.curvature(s))))
        if k < best_k:
            best, best_k = float(s0), k
    assert best is not None
    return best


def place(race, s, n=0.0, v=0.0, car=0, update_frenet=True):
    """Put a controlled car at Frenet (s, n), aligned with the raceline, steering 0."""
    x, y = race.track.to_cartesian(s, n)
    race.states[car] = (x, y, race.track.heading(s), v, 0.0)
    if update_frenet:
        race.frenet[car] = (race.track.wrap(s), n, 0.0, v, 0.0)


def make_race(track, n_opponents=0, **opp):
    cfg = RaceConfig(random_start=False, opponents=OpponentConfig(n_opponents=n_opponents, **opp))
    race = Race(track, cfg)
    race.reset(np.random.default_rng(0), start_speed=0.0)
    return race


def test_scripted_overtake_is_counted_once_and_the_opponent_respawns_ahead(track):
    s0 = straightest(track, span=80.0, need_left=6.0)
    race = make_race(track, n_opponents=1, gaps=(10.0,), offsets=(0.0,), rho=0.0)  # a parked car
    place(race, s0, n=0.0)
    race.opponents.reset(s0, rho=0.0)
    opp_s = float(race.opponents.s[0])
    assert track.gap(opp_s, s0) == pytest.approx(10.0)
    counted = []
    for k in range(1, 40):  # the ego passes on the left at 10 m/s, 3.5 m beside it
        place(race, s0 + 1.0 * (k - 1), n=3.5, v=10.0)
        ev = race.step(ZERO)[0]
        assert not ev.collision and not ev.off_track
        counted.append(ev.overtakes)
        if ev.overtakes:
            ego_s = race.frenet[0, 0]
            assert track.gap(opp_s, ego_s) <= -race.config.opponents.overtake_threshold
            # respawned respawn_distance ahead of the ego
            assert race.opponents.rel[0] == pytest.approx(race.config.opponents.respawn_distance)
            assert track.gap(race.opponents.s[0], ego_s) == pytest.approx(race.config.opponents.respawn_distance)
    assert sum(counted) == 1
    assert race.overtakes[0] == 1
    # the pass happens when the ego is ~12 m further (10 m gap + 2 m threshold)
    assert 11 <= int(np.argmax(counted)) + 1 <= 14


def test_a_car_that_is_never_ahead_is_not_counted(track):
    s0 = straightest(track)
    race = make_race(track, n_opponents=1, gaps=(300.0,), offsets=(0.0,), rho=0.0)
    place(race, s0)
    race.opponents.reset(s0, rho=0.0)
    for k in range(20):  # the ego drives backwards, away from the opponent
        place(race, s0 - 1.0 * k, v=0.0)
        assert race.step(ZERO)[0].overtakes == 0


@pytest.mark.parametrize(
    "ds, dn, expected",
    [
        (4.8, 0.0, True),   # nose to tail, 10 cm overlap (footprint length 4.9 m)
        (5.1, 0.0, False),  # 20 cm gap
        (0.0, 1.8, True),   # side by side, 10 cm overlap (width 1.9 m)
        (0.0, 2.1, False),
        (-4.8, 0.0, True),  # an opponent just behind
    ],
)
def test_collision_with_real_footprints(track, ds, dn, expected):
    s0 = straightest(track, span=20.0, need_left=3.0)
    race = make_race(track, n_opponents=1, gaps=(50.0,), offsets=(0.0,), rho=0.0)
    place(race, s0)
    race.opponents.s[:] = track.wrap(s0 + ds)
    race.opponents.n[:] = dn
    ev = race.step(ZERO)[0]  # v = 0: nobody moves
    assert ev.collision is expected
    assert not ev.off_track


def test_collision_between_controlled_cars(track):
    s0 = straightest(track, span=20.0)
    race = Race(track, RaceConfig(random_start=False, opponents=OpponentConfig(n_opponents=0)), n_cars=2)
    race.reset(np.random.default_rng(0), start_s=s0, start_speed=0.0)
    place(race, s0, car=0)
    place(race, s0 + 4.0, car=1)
    events = race.step(np.zeros((2, 2)))
    assert events[0].collision and events[1].collision
    race.deactivate(1)  # a crashed car no longer counts as an obstacle
    assert not race.step(np.zeros((2, 2)))[0].collision


def test_off_track_uses_the_footprint_corners(track):
    """The corner test: the footprint's outer side 0.5 m inside vs 0.2 m beyond the left edge."""
    s0 = straightest(track, span=20.0)
    half_w = 0.5 * RaceConfig().vehicle.width
    wl = float(track.width_left(s0))
    for n, expected in [(wl - half_w - 0.5, False), (wl - half_w + 0.2, True), (wl - 0.5, True),
                        (wl + 0.2, True), (0.0, False)]:
        race = make_race(track)
        place(race, s0, n=n)
        assert race.step(ZERO)[0].off_track is expected, n
    wr = float(track.width_right(s0))
    for n, expected in [(-(wr - half_w - 0.5), False), (-(wr - half_w + 0.2), True)]:
        race = make_race(track)
        place(race, s0, n=n)
        assert race.step(ZERO)[0].off_track is expected, n


def test_off_track_prefilter_agrees_with_the_corner_projections(track):
    """The world skips the corner projections away from the edges; check it against projecting every corner."""
    from sofar_env.geometry import footprint_corners

    race = make_race(track)
    p = race.config.vehicle
    rng = np.random.default_rng(3)
    outcomes = []
    for _ in range(400):
        s = rng.uniform(0.0, track.length)
        wl, wr = float(track.width_left(s)), float(track.width_right(s))
        n = rng.uniform(-wr - 1.0, wl + 1.0)
        x, y = track.to_cartesian(s, n)
        psi = track.heading(s) + rng.uniform(-0.3, 0.3)
        race.states[0, :3] = (x, y, psi)
        race.frenet[0, :2] = (s, n)
        corners = footprint_corners(x, y, psi, p)
        cs, cn = track.to_frenet(corners[:, 0], corners[:, 1], s_hint=np.full(4, s))
        exact = bool(np.any(cn > track.width_left(cs)) or np.any(cn < -track.width_right(cs)))
        assert race._off_track(0) is exact, (s, n, psi)
        outcomes.append(exact)
    assert 0.1 < np.mean(outcomes) < 0.9  # both cases were exercised


def test_same_seed_same_world(track):
    def run(seed):
        race = Race(track, RaceConfig(opponents=OpponentConfig(rho=0.4)))
        race.reset(np.random.default_rng(seed))
        u = np.array([[0.5, 0.01]])
        for _ in range(30):
            race.step(u)
        return race.states.copy(), race.frenet.copy(), race.opponents.s.copy(), race.distance.copy()

    a, b, c = run(7), run(7), run(8)
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x, y)
    assert not np.array_equal(a[0], c[0])


def test_laps_is_progress_over_length_on_a_full_lap(track):
    race = make_race(track)
    s0 = 123.0
    place(race, s0)
    step = 10.0
    n_steps = int(np.ceil(track.length / step))
    for k in range(1, n_steps + 1):
        # teleport along the raceline; the world projects the new position with its previous s as the hint
        place(race, s0 + min(k * step, track.length), update_frenet=False)
        ev = race.step(ZERO)[0]
        assert ev.progress == pytest.approx(min(step, track.length - (k - 1) * step), abs=1e-6)
    assert race.laps() == pytest.approx(1.0, abs=1e-6)
    assert race.distance[0] == pytest.approx(track.length, abs=1e-6)


def test_truncation_at_the_duration(track):
    race = Race(track, replace(RaceConfig(), duration=0.5))
    race.reset(np.random.default_rng(0))
    flags = []
    for _ in range(5):
        race.step(ZERO)
        flags.append(race.truncated)
    assert flags == [False, False, False, False, True]


def test_more_opponents_than_gaps_spawn_apart(track):
    """The gap list repeats further ahead (shifted by its largest entry), never onto the same spot."""
    race = make_race(track, n_opponents=8)
    rel = np.sort(race.opponents.rel)
    assert np.allclose(rel, [120.0, 180.0, 250.0, 400.0, 520.0, 580.0, 650.0, 800.0])
    assert np.min(np.diff(rel)) >= 50.0
    with pytest.raises(ValueError, match="largest gap"):
        OpponentConfig(n_opponents=2, gaps=(-10.0,))


# ---------------------------------------------------------------------- the multi-car grid
GRID_TRACKS = ["LagunaSeca", "Monza", "Indianapolis", "Kentucky"]


@pytest.mark.parametrize("name", GRID_TRACKS)
def test_grid_start_inside_the_edges_without_overlaps(name):
    """200 seeded grid starts of 5 cars per circuit: every footprint corner at least 0.3 m inside both
    edges (projected exactly), no two footprints intersecting, consecutive cars 2 grid slots apart."""
    from sofar_env.geometry import footprint_corners, rectangles_intersect

    track = Track.load(name)
    cfg = RaceConfig(opponents=OpponentConfig(n_opponents=0))
    race = Race(track, cfg, n_cars=5)
    lateral = []
    for seed in range(200):
        race.reset(np.random.default_rng(seed))
        st = race.states
        corners = footprint_corners(st[:, 0], st[:, 1], st[:, 2], cfg.vehicle)  # (5, 4, 2)
        cs, cn = track.to_frenet(corners[..., 0].ravel(), corners[..., 1].ravel(),
                                 s_hint=np.repeat(race.frenet[:, 0], 4))
        assert np.all(cn <= track.width_left(cs) - 0.3), (name, seed)
        assert np.all(cn >= -track.width_right(cs) + 0.3), (name, seed)
        overlap = rectangles_intersect(corners[:, None], corners[None, :])
        assert not np.any(overlap[~np.eye(5, dtype=bool)]), (name, seed)
        gaps = track.gap(race.frenet[:-1, 0], race.frenet[1:, 0])  # each car behind the one before it
        np.testing.assert_allclose(gaps, [12.0, 12.0, 12.0, 12.0], atol=1e-9)
        assert race.frenet[4, 1] == 0.0  # alone in the last row: on the raceline
        lateral += [race.frenet[0, 1] - race.frenet[1, 1], race.frenet[2, 1] - race.frenet[3, 1]]
    lateral = np.array(lateral)
    assert np.all(lateral > 0.0)  # the first car of a row is always left of the second
    assert np.mean(np.isclose(lateral, 4.0)) > 0.8  # two abreast, 2 x grid_lateral_offset apart where it fits


def test_grid_layout_where_the_track_is_wide(track):
    # a stretch with room for 2 m offsets either side (footprint half-width 0.95 m + 0.5 m margin)
    s = np.arange(0.0, track.length, 1.0)
    wide = (track.width_left(s) > 3.6) & (track.width_right(s) > 3.6)
    pole = next(float(x) for x in s if np.all(wide[(np.arange(int(x) - 60, int(x) + 20)) % len(s)]))
    race = Race(track, RaceConfig(random_start=False, start_s=pole), n_cars=4)
    race.reset(np.random.default_rng(0), start_speed=20.0)
    np.testing.assert_allclose(race.frenet[:, 0], track.wrap(pole - np.array([0.0, 12.0, 24.0, 36.0])))
    np.testing.assert_allclose(race.frenet[:, 1], [2.0, -2.0, 2.0, -2.0])
    np.testing.assert_allclose(race.frenet[:, 3], 20.0)
    s0 = straightest(track, span=60.0)
    single = Race(track, RaceConfig(random_start=False, start_s=s0), n_cars=1)
    single.reset(np.random.default_rng(0))
    assert single.frenet[0, 0] == pytest.approx(s0) and single.frenet[0, 1] == 0.0  # a lone car: on the raceline


@pytest.mark.parametrize("field, value, match", [
    ("grid_stagger", 5.0, "at least the car length"),
    ("grid_row_spacing", 18.0, "at least the car length"),
    ("grid_lateral_offset", -1.0, "grid_lateral_offset"),
    ("grid_row_spacing", float("nan"), "grid_row_spacing"),
    ("pace_range", (1.0, 0.9), "pace_range"),
    ("pace_range", (0.0, 0.9), "pace_range"),
    ("pace_range", (0.9,), "pace_range"),
])
def test_grid_and_pace_are_validated(field, value, match):
    with pytest.raises(ValueError, match=match):
        RaceConfig(**{field: value})


def test_a_grid_longer_than_the_lap_is_rejected(track):
    with pytest.raises(ValueError, match="does not fit"):
        Race(track, RaceConfig(grid_row_spacing=1000.0, grid_stagger=12.0), n_cars=10)


def test_an_overtake_between_controlled_cars_is_counted_once_for_the_passer(track):
    s0 = straightest(track, span=80.0, need_left=4.0)
    race = Race(track, RaceConfig(random_start=False, start_s=s0 + 10.0), n_cars=2)
    race.reset(np.random.default_rng(0), start_speed=0.0)
    place(race, s0 + 10.0, n=-2.0, car=0)  # car 0 parked 10 m ahead, car 1 passes on its left
    counts = []
    for k in range(30):
        place(race, s0 + 1.0 * k, n=2.0, v=10.0, car=1)
        place(race, s0 + 10.0, n=-2.0, car=0)
        events = race.step(np.zeros((2, 2)))
        assert not events[1].collision
        counts.append((events[0].overtakes, events[1].overtakes))
    counts = np.array(counts)
    assert counts[:, 0].sum() == 0 and counts[:, 1].sum() == 1  # the passer only, once
    # credited when car 0 is overtake_threshold (2 m) behind: car 1 at s0 + 12
    assert int(np.argmax(counts[:, 1])) == 12
    for k in range(30):  # car 0 re-passes car 1, parked 19 m further: credited to car 0, once
        place(race, s0 + 10.0 + 1.0 * k, n=-2.0, v=10.0, car=0)
        place(race, s0 + 29.0, n=2.0, car=1)
        events = race.step(np.zeros((2, 2)))
        counts = np.vstack([counts, [events[0].overtakes, events[1].overtakes]])
    assert counts[:, 0].sum() == 1 and counts[:, 1].sum() == 1
    assert race.overtakes.tolist() == [1, 1]
