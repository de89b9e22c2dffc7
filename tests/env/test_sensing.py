"""The sensor model of the opponents: identity when off; latency, Gauss-Markov noise and the tracker when on."""

import math

import numpy as np
import pytest

from sofar_env.sensing import Sensor, SensorConfig

L, DT = 3588.0, 0.1


def sensor(seed=0, **kw):
    s = Sensor(SensorConfig(enabled=True, **kw), L, DT)
    s.reset(np.random.default_rng(seed))
    return s


def test_disabled_is_the_identity_and_draws_nothing():
    sen = Sensor(SensorConfig(), L, DT)
    rng = np.random.default_rng(1)
    state = rng.bit_generator.state
    sen.reset(rng)
    rows = np.array([[10.0, 0.5, 30.0], [3587.9, -1.0, 0.0]])
    out = sen.measure(rows, [3, 7])
    assert rng.bit_generator.state == state
    assert np.array_equal(out[:, :3], rows) and np.array_equal(out[:, 3], [0.0, 0.0])
    rows4 = np.column_stack([rows, [0.2, -0.1]])
    assert np.array_equal(sen.measure(rows4, [3, 7]), rows4)
    assert sen.measure(np.zeros((0, 3)), []).shape == (0, 4)


def test_same_seed_same_measurements():
    rows = np.array([[100.0, 0.5, 30.0], [200.0, -1.0, 25.0]])
    a, b, c = (sensor(seed) for seed in (4, 4, 5))
    for k in range(20):
        step = rows + [DT * k * 30.0, 0.0, 0.0]
        ra, rb, rc = a.measure(step, [0, 1]), b.measure(step, [0, 1]), c.measure(step, [0, 1])
        assert np.array_equal(ra, rb)
    assert not np.array_equal(ra, rc)


def test_noise_has_the_configured_spread_and_correlation():
    cfg = dict(sigma_s=1.0, sigma_n=0.3, sigma_v=0.5, correlation_time=0.3, latency_steps=0)
    sen = sensor(2, **cfg)
    m, steps = 50, 2000
    truth = np.column_stack([np.linspace(100.0, 3000.0, m), np.full(m, 0.5), np.full(m, 30.0)])
    err = np.empty((steps, m, 3))
    for k in range(steps):
        out = sen.measure(truth, range(m))
        d = out[:, :3] - truth
        d[:, 0] = (d[:, 0] + 0.5 * L) % L - 0.5 * L
        err[k] = d
    sig = np.array([1.0, 0.3, 0.5])
    phi = math.exp(-DT / 0.3)
    flat = err.reshape(-1, 3)
    # the mean of correlated samples: about N (1 - phi) / (1 + phi) independent ones
    n_eff = flat.shape[0] * (1 - phi) / (1 + phi)
    assert np.all(np.abs(flat.mean(0)) < 4 * sig / math.sqrt(n_eff))
    assert flat.std(0) == pytest.approx(sig, rel=0.05)
    lag1 = (err[1:] * err[:-1]).mean((0, 1)) / (err * err).mean((0, 1))
    assert lag1 == pytest.approx([phi] * 3, abs=0.02)
    lag3 = (err[3:] * err[:-3]).mean((0, 1)) / (err * err).mean((0, 1))
    assert lag3 == pytest.approx([phi ** 3] * 3, abs=0.03)


def test_latency_is_exactly_k_steps():
    for k_lat in (0, 1, 3):
        sen = sensor(0, sigma_s=0.0, sigma_n=0.0, sigma_v=0.0, latency_steps=k_lat, latency_compensation=False)
        truth = [np.array([[100.0 + 3.0 * t, 0.1 * t, 30.0 + t]]) for t in range(12)]
        outs = [sen.measure(row, [9])[0, :3] for row in truth]
        for t in range(12):
            assert np.allclose(outs[t], truth[max(t - k_lat, 0)][0], atol=1e-12)


def test_latency_compensation_carries_the_measurement_forward_over_its_age():
    # a car at a constant 42 m/s and a constant lateral rate: without compensation it is seen
    # v * latency = 8.4 m behind; with it, exactly where it is once the tracker has the rate
    v, rate, k_lat = 42.0, 0.4, 2
    truth = [np.array([[100.0 + v * DT * t, -1.0 + rate * DT * t, v]]) for t in range(80)]
    raw = sensor(0, sigma_s=0.0, sigma_n=0.0, sigma_v=0.0, latency_steps=k_lat, latency_compensation=False)
    comp = sensor(0, sigma_s=0.0, sigma_n=0.0, sigma_v=0.0, latency_steps=k_lat)
    out_raw = np.array([raw.measure(row, [3])[0] for row in truth])
    out_comp = np.array([comp.measure(row, [3])[0] for row in truth])
    true = np.array([row[0] for row in truth])
    assert np.allclose(out_raw[10:, 0] - true[10:, 0], -v * k_lat * DT, atol=1e-9)
    assert np.allclose(out_comp[10:, 0], true[10:, 0], atol=1e-9)  # s: the measured speed is exact
    assert np.abs(out_comp[-1, 1] - true[-1, 1]) < 1e-3  # n: once the tracker has converged
    assert np.abs(out_raw[-1, 1] - true[-1, 1]) == pytest.approx(rate * k_lat * DT, abs=1e-3)
    # a young track (fewer measurements than the latency) is carried over its actual age
    young = sensor(0, sigma_s=0.0, sigma_n=0.0, sigma_v=0.0, latency_steps=k_lat)
    first = young.measure(truth[0], [3])[0]
    second = young.measure(truth[1], [3])[0]
    assert first[0] == pytest.approx(true[0, 0]) and second[0] == pytest.approx(true[0, 0] + v * DT)


def test_the_tracker_picks_up_a_constant_lateral_rate():
    rate = 0.4
    sen = sensor(0, sigma_s=0.0, sigma_n=0.0, sigma_v=0.0)
    est = [sen.measure([[100.0 + 30.0 * DT * t, -1.0 + rate * DT * t, 30.0]], [1])[0, 3] for t in range(60)]
    assert est[0] == 0.0
    assert abs(est[-1] - rate) < 1e-3
    assert abs(est[30] - rate) < 0.02  # within 3 s
    # with noise, unbiased on average
    noisy = sensor(1)
    est = [noisy.measure([[100.0 + 30.0 * DT * t, -1.0 + rate * DT * t, 30.0]], [1])[0, 3] for t in range(5000)]
    assert np.mean(est[100:]) == pytest.approx(rate, abs=0.03)


def test_arc_length_is_wrapped_into_the_lap():
    sen = sensor(0, sigma_s=5.0)
    out = np.array([sen.measure([[L - 0.01, 0.0, 30.0], [0.01, 0.0, 30.0]], [0, 1])[:, 0] for _ in range(300)])
    assert out.min() >= 0.0 and out.max() < L
    assert (out > L / 2).any() and (out < L / 2).any()  # noise crosses the start line both ways


def test_a_jump_restarts_the_track_and_absent_ids_are_forgotten():
    sen = sensor(0, sigma_s=0.0, sigma_n=0.0, sigma_v=0.0, latency_steps=2)
    for t in range(5):
        sen.measure([[100.0 + t, 0.0, 30.0]], [4])
    out = sen.measure([[600.0, 1.0, 20.0]], [4])  # a respawn that kept its identity
    assert np.allclose(out[0, :3], [600.0, 1.0, 20.0]) and out[0, 3] == 0.0
    sen.measure([[601.0, 1.0, 20.0]], [5])  # id 4 absent: forgotten
    out = sen.measure([[700.0, 2.0, 20.0]], [4])
    assert np.allclose(out[0, :3], [700.0, 2.0, 20.0])


def test_bad_input_and_settings_raise():
    sen = sensor(0)
    with pytest.raises(ValueError):
        sen.measure(np.zeros((2, 3)), [1, 1])
    with pytest.raises(ValueError):
        sen.measure(np.zeros((2, 2)), [1, 2])
    with pytest.raises(RuntimeError):
        Sensor(SensorConfig(enabled=True), L, DT).measure(np.zeros((1, 3)), [0])
    for bad in (dict(sigma_s=-1.0), dict(correlation_time=0.0), dict(latency_steps=-1), dict(latency_steps=1.5),
                dict(tracker_alpha=0.0), dict(tracker_beta=2.0)):
        with pytest.raises(ValueError):
            SensorConfig(**bad)
