"""The compiled and Python-float paths of the world's step give the very same numbers (bit for bit) as the
numpy forms they replaced: the track's periodic algebra (floor modulo, array gap, scalar interpolation,
poses), the opponent field's motion and overtake bookkeeping, the race's distance and contact prefilter,
the observation's scaling and mean curvature, and the sensor."""

import math
from collections import deque

import numpy as np
import pytest

from sofar_env.tracks import Track


@pytest.fixture(scope="module")
def laguna():
    return Track.load("LagunaSeca")


def _special(length):
    """Arc lengths at and around the period's ends, zeros, infinities and nan."""
    return [0.0, -0.0, length, -length, 2.0 * length, -2.0 * length, float(np.nextafter(length, 0.0)),
            float(np.nextafter(length, np.inf)), float(np.nextafter(2.0 * length, 0.0)),
            float(np.nextafter(-length, 0.0)), float(np.nextafter(-length, -np.inf)), 5e-324, -5e-324,
            -1e-13, math.inf, -math.inf, math.nan, 1e308, -1e308]


@pytest.mark.parametrize("length", [3602.5, 1.0, 3.7, 1e-300, 1e300])
def test_floor_mod_is_numpys_mod(length):
    from sofar_env.tracks.curve import floor_mod

    rng = np.random.default_rng(0)
    x = np.concatenate([_special(length), rng.uniform(-3 * length, 3 * length, 20000),
                        rng.normal(size=2000) * length * 1e-17])
    with np.errstate(invalid="ignore"):
        ref = np.mod(x, length)
    assert np.array([floor_mod(v, length) for v in x.tolist()]).tobytes() == ref.tobytes()


def test_array_gap_is_the_numpy_form(laguna):
    track, L = laguna, laguna.length
    rng = np.random.default_rng(1)
    a = np.concatenate([_special(L), rng.uniform(-1.5 * L, 2.5 * L, 5000), track.s])
    b = np.concatenate([_special(L)[::-1], rng.uniform(-L, 2.0 * L, a.size - len(_special(L)))])
    half = 0.5 * L
    with np.errstate(invalid="ignore"):
        for sa, sb in ((a, b), (a, 1234.5), (a[:, None], b[None, :50]), (a.tolist(), np.float64(7.0))):
            ref = track._curve.wrap(np.subtract(sa, sb, dtype=float) + half) - half
            new = track.gap(sa, sb)
            assert type(new) is np.ndarray and new.shape == ref.shape and new.tobytes() == ref.tobytes()


def test_compiled_scalar_interpolation_is_the_python_one(laguna):
    from sofar_env.tracks.curve import lerp_wrapped

    track, L = laguna, laguna.length
    values = _special(L) + np.random.default_rng(2).uniform(-1.5 * L, 2.5 * L, 5000).tolist() + track.s.tolist()
    for key in ("kappa", "wl", "wr", "v"):
        closed, closed_list = track._tables[key]
        ref = np.array([track._interp_scalar(closed_list, v) for v in values])
        assert np.array([lerp_wrapped(v, L, track._knots, closed) for v in values]).tobytes() == ref.tobytes()
    assert type(track.speed(np.float64(3.0))) is float and track.speed(np.float64(3.0)) == track.speed(3.0)


def test_poses_are_the_scalar_poses(laguna):
    track, L = laguna, laguna.length
    rng = np.random.default_rng(3)
    s = np.concatenate([[0.0, L, -L, 2.0 * L, np.nextafter(L, 0.0), -1e-13, -0.0], track.s,
                        rng.uniform(-1.5 * L, 2.5 * L, 5000)])
    n = rng.uniform(-15.0, 15.0, s.size)
    ref = np.array([track.pose(a, b) for a, b in zip(s.tolist(), n.tolist())])
    for col, new in zip(ref.T, track.poses(s, n)):
        assert new.tobytes() == col.tobytes()
    assert all(a.shape == (0,) for a in track.poses(np.zeros(0), np.zeros(0)))


def test_field_advance_and_overtakes_are_the_numpy_forms(laguna):
    from sofar_env.opponents.field import _advance_on_profile, _unwrap_gaps

    track, L = laguna, laguna.length
    rng = np.random.default_rng(4)
    knots, table = track.table("v")
    for _ in range(300):
        m = int(rng.integers(1, 8))
        s = rng.uniform(0.0, L, m)
        s[0] = float(np.nextafter(L, 0.0)) if rng.random() < 0.2 else s[0]
        rho, dt = float(rng.uniform(0.0, 2.0)), float(rng.choice([0.1, 0.05, 0.3]))
        ref_s = [track.wrap(x + dt * rho * track.speed(x + 0.5 * dt * (rho * track.speed(x)))) for x in s.tolist()]
        ref_v = [rho * track.speed(x) for x in ref_s]
        new_s, new_v = np.empty(m), np.empty(m)
        _advance_on_profile(s, rho, dt, L, knots, table, new_s, new_v)
        assert new_s.tolist() == ref_s and new_v.tolist() == ref_v

        ego = float(rng.uniform(-L, 2.0 * L))
        rel = rng.uniform(-0.6 * L, 0.6 * L, m)
        was = rng.random(m) < 0.5
        thr = float(rng.uniform(1.0, 30.0))
        gap = np.asarray(track._curve.wrap(s - ego + 0.5 * L) - 0.5 * L, float)
        ref_rel = rel + ((gap - rel + 0.5 * L) % L - 0.5 * L)
        ref_was = was | (ref_rel > 0.0)
        ref_passed = (ref_was & (ref_rel <= -thr)).nonzero()[0]
        new_rel, passed = np.empty(m), np.empty(m, np.int64)
        k = _unwrap_gaps(s, ego, rel, was, L, thr, new_rel, passed)
        assert new_rel.tobytes() == ref_rel.tobytes() and np.array_equal(was, ref_was)
        assert np.array_equal(passed[:k], ref_passed)


def test_race_distance_and_prefilter_are_the_numpy_forms():
    from sofar_env.race import _nearest, _within

    rng = np.random.default_rng(5)
    assert _nearest(np.zeros(0), np.zeros(0), 1.0, 2.0) == math.inf
    for _ in range(2000):
        m = int(rng.integers(1, 9))
        x, y = rng.uniform(-500, 500, m), rng.uniform(-500, 500, m)
        xk, yk = float(rng.uniform(-500, 500)), float(rng.uniform(-500, 500))
        if rng.random() < 0.1:
            x[0] = math.nan
        d = _nearest(x, y, xk, yk)
        ref = float(np.hypot(x - xk, y - yk).min())
        assert d == ref or (math.isnan(d) and math.isnan(ref))
        reach2 = float(rng.uniform(0.0, 1e5))
        near = np.empty(m, bool)
        found = _within(x, y, xk, yk, reach2, near)
        # squares as products (the replaced list used ** 2, which can differ by an ulp: the prefilter has 1 mm
        # of slack, so no pair within an ulp of its bound can touch, and collisions are the same)
        ref_near = [(xo - xk) * (xo - xk) + (yo - yk) * (yo - yk) < reach2 for xo, yo in zip(x.tolist(), y.tolist())]
        assert near.tolist() == ref_near and found == any(ref_near)


def test_observation_scaling_is_the_numpy_form():
    from sofar_env.observation import (
        _EXT_HIGH,
        _EXT_LOW,
        _EXT_SPAN,
        _SPAN,
        OBS_HIGH,
        OBS_LOW,
        _scale_clipped,
        scale,
    )

    rng = np.random.default_rng(6)
    special = [0.0, -0.0, math.nan, math.inf, -math.inf, 1e-300]
    for k in range(5000):
        raw = rng.uniform(-1.5, 1.5, 12) * _SPAN + OBS_LOW
        extra = rng.uniform(-2.0, 2.0, 4) * _EXT_SPAN + _EXT_LOW
        if k % 3 == 0:
            raw[rng.integers(0, 12, 4)] = rng.choice(special + OBS_LOW.tolist() + OBS_HIGH.tolist(), 4)
            extra[rng.integers(0, 4, 2)] = rng.choice(special + _EXT_LOW.tolist() + _EXT_HIGH.tolist(), 2)
        ref = np.minimum(np.maximum(raw, OBS_LOW), OBS_HIGH)
        ref = ((((ref - OBS_LOW) * 2.0) / _SPAN) - 1.0).astype(np.float32)
        assert scale(raw).tobytes() == ref.tobytes()
        assert scale(raw[None]).tobytes() == ref.tobytes()  # the general path
        ref = (2.0 * (np.clip(extra, _EXT_LOW, _EXT_HIGH) - _EXT_LOW) / _EXT_SPAN - 1.0).astype(np.float32)
        out = np.empty(4, np.float32)
        _scale_clipped(extra, _EXT_LOW, _EXT_HIGH, _EXT_SPAN, out)
        assert out.tobytes() == ref.tobytes()


@pytest.mark.parametrize("n", [8, 9, 15, 16, 17, 33, 128])
def test_mean_curvature_is_numpys_sum_of_the_interpolation(laguna, n):
    from sofar_env.observation import _curvature_sum

    track, L = laguna, laguna.length
    knots, table = track.table("kappa")
    tau = np.linspace(0.0, 1.5, n)
    rng = np.random.default_rng(n)
    for k in range(2000):
        s = float(rng.uniform(-L, 2.0 * L)) if k % 10 else float(rng.choice([0.0, L, np.nextafter(L, 0.0)]))
        v = float(rng.uniform(5.0, 120.0)) if k % 7 else float(rng.uniform(5.0, 5000.0))
        assert _curvature_sum(s, v, tau, L, knots, table) == float(np.add.reduce(track.curvature(s + v * tau)))


class _Track:
    """Per-identity state of the reference sensor: noise, delay line, tracker."""

    def __init__(self, noise, latency, s):
        self.noise = noise
        self.delay = deque(maxlen=latency + 1)
        self.n_hat = None
        self.n_dot_hat = 0.0
        self.last_s = s


def _track_rate(sensor, tr, n_meas):
    """One alpha-beta step of the reference sensor's tracker on the delayed lateral measurement."""
    if tr.n_hat is None:
        tr.n_hat, tr.n_dot_hat = n_meas, 0.0
        return 0.0
    a, b, dt = sensor.config.tracker_alpha, sensor.config.tracker_beta, sensor.dt
    predicted = tr.n_hat + dt * tr.n_dot_hat
    r = n_meas - predicted
    tr.n_hat = predicted + a * r
    tr.n_dot_hat += b / dt * r
    return tr.n_dot_hat


def _reference_measure(sensor, rows, ids):
    """The sensor's measurement written on numpy 3-vectors with a dict of tracks (the form it replaced); its
    state lives in ``sensor.reference_tracks``."""
    cfg, L = sensor.config, sensor.length
    sig = cfg.sigmas
    m = rows.shape[0]
    fresh = sensor._rng.standard_normal((m, 3))
    gain = math.sqrt(max(1.0 - sensor.phi * sensor.phi, 0.0))
    tracks, out = {}, np.zeros((m, 4))
    for k, (key, row) in enumerate(zip(ids, rows)):
        s_true = float(row[0])
        tr = sensor.reference_tracks.get(key)
        if tr is None or abs((s_true - tr.last_s + 0.5 * L) % L - 0.5 * L) > cfg.jump_distance:
            tr = _Track(sig * fresh[k], cfg.latency_steps, s_true)
        else:
            tr.noise = sensor.phi * np.asarray(tr.noise) + gain * sig * fresh[k]
        tr.last_s = s_true
        z = row + tr.noise
        z[0] %= L
        if z[0] >= L:
            z[0] = 0.0
        tr.delay.append(z)
        seen = tr.delay[0]
        out[k, :3] = seen
        out[k, 3] = rate = _track_rate(sensor, tr, float(seen[1]))
        age = (len(tr.delay) - 1) * sensor.dt
        if cfg.latency_compensation and age > 0.0:
            s_now = (seen[0] + seen[2] * age) % L
            out[k, 0] = s_now if s_now < L else 0.0
            out[k, 1] = seen[1] + rate * age
        tracks[key] = tr
    sensor.reference_tracks = tracks
    return out


@pytest.mark.parametrize(("compensate", "latency"), [(True, 2), (False, 2), (True, 0), (True, 1), (False, 5)])
def test_sensor_is_the_numpy_form(compensate, latency):
    from sofar_env.sensing import Sensor, SensorConfig

    cfg = SensorConfig(enabled=True, latency_compensation=compensate, latency_steps=latency)
    L = 3602.5
    new, ref = Sensor(cfg, L, 0.1), Sensor(cfg, L, 0.1)
    new.reset(np.random.default_rng(8))
    ref.reset(np.random.default_rng(8))
    ref.reference_tracks = {}
    rng = np.random.default_rng(9)
    s = rng.uniform(0.0, L, 5)
    for step in range(400):
        s = (s + rng.uniform(0.0, 9.0, 5)) % L
        if step % 50 == 7:
            s[1] = (s[1] + 500.0) % L  # a jump restarts the track
        if step % 97 == 3:
            s[2] = float(np.nextafter(L, 0.0))
        rows = np.column_stack([s, rng.uniform(-5.0, 5.0, 5), rng.uniform(10.0, 80.0, 5)])
        ids = [0, 1, 2, 3, 4] if step % 30 < 25 else [0, 2, 4, 5, 6]  # identities come and go
        got = new.measure(rows, ids)
        want = _reference_measure(ref, rows, ids)
        assert got.shape == (5, 4) and got.tobytes() == want.tobytes()
    assert new.measure(np.zeros((0, 3)), []).shape == (0, 4)
