"""How the controlled car sees the opponents: a sensor model with latency, correlated noise and a tracker.

:class:`Sensor` turns the true opponent rows ``(s, n, v)`` (absolute arc length
[m], lateral offset [m], arc-length speed [m/s]) into sensed rows
``(s, n, v, n_dot)``. With :class:`SensorConfig` ``enabled = False`` (the default)
sensing is perfect: the rows come back unchanged (a lateral-rate column appended
if the caller gave none) and no random number is drawn. Enabled, per opponent
identity and control step:

* the measurement is the true row plus noise, each component a first-order
  Gauss-Markov process ``e_{k+1} = phi e_k + sqrt(1 - phi^2) sigma w_k`` with
  ``phi = exp(-dt / tau)`` and ``w_k ~ N(0, 1)``, started from its stationary
  distribution ``N(0, sigma^2)``: the noise has standard deviation ``sigma`` and
  autocorrelation ``exp(-|lag| / tau)``, so it persists over several steps and does
  not average out the way white noise would;
* the output is the measurement of ``latency_steps`` steps earlier (for a track
  younger than that, its first measurement); ``s`` is wrapped into ``[0, L)``;
* ``n_dot`` is the estimate of an alpha-beta tracker run on the delayed lateral
  measurements (it follows a constant lateral rate without steady-state error);
* with ``latency_compensation`` (the default) the delayed measurement is carried
  forward over its known age at the measured rates, ``s + v * age`` and
  ``n + n_dot * age``, the constant-velocity propagation every racing perception
  stack applies to time-stamped object lists. Without it, a car at 42 m/s is seen
  8.4 m behind where it is after 0.2 s of latency, although its gap to the ego
  changed by only (v_ego - v) * 0.2 s: the ego's own pose is current, so an
  uncompensated absolute position mixes two times. With it, what remains is the
  noise, the speed error times the age (0.5 m/s x 0.2 s = 0.1 m) and what the car
  did during the age that constant velocity misses (a lift, a defensive move).

An identity whose true arc length jumps by more than ``jump_distance`` between two
calls (a respawn that kept its identity) has its track restarted; identities
absent from a call are forgotten.

Default values: the sensor and its errors are an assumption of this package, not a
model of a particular car. Object lists from LiDAR/radar fusion at the ranges that
matter for overtaking (tens of metres) are taken to be good to about a metre along
the track, where a car's extent and the range error enter, and a few decimetres
across it (sigma 1.0 m / 0.3 m), with speed errors of about 0.5 m/s; the 0.2 s of
latency (2 control steps at the 0.1 s control period) stands for detection,
tracking and transport; the 0.3 s correlation time is a few sensor frames, the time
a detection error of a clustered point cloud typically persists.
"""

from __future__ import annotations

import math

import numpy as np

from ._jit import kernel
from .configs.sensing import SensorConfig

__all__ = ["SensorConfig", "Sensor"]




class Sensor:
    """Sensor of the opponents on a track of length ``track_length`` [m], called once every ``dt`` [s]."""

    def __init__(self, config: SensorConfig, track_length: float, dt: float):
        if not (track_length > 0.0 and dt > 0.0):
            raise ValueError("track_length and dt must be positive")
        self.config = config
        self.length = float(track_length)
        self.dt = float(dt)
        self.phi = math.exp(-self.dt / config.correlation_time)
        """Step correlation of the noise, exp(-dt / tau)."""
        self._rng: np.random.Generator | None = None
        self._tracks = _empty_tracks(0, int(config.latency_steps) + 1)

    def reset(self, rng: np.random.Generator | None = None) -> None:
        """Forget every track; when enabled, seed the sensor's own generator from ``rng`` (one draw)."""
        self._tracks = _empty_tracks(0, int(self.config.latency_steps) + 1)
        self._rng = None
        if self.config.enabled:
            if rng is None:
                raise ValueError("an rng is required when the sensor is enabled")
            self._rng = np.random.default_rng(int(rng.integers(0, 2 ** 63)))

    def measure(self, true_rows, ids) -> np.ndarray:
        """Sensed rows ``(s, n, v, n_dot)`` (M, 4) of the true rows ``(s, n, v[, n_dot])`` (M, 3 or 4).

        ``ids``: a stable integer identity per row. Disabled: the given columns unchanged (with
        ``n_dot = 0`` appended to rows of three columns).
        """
        rows = np.asarray(true_rows, float)
        if rows.ndim != 2 or rows.shape[1] not in (3, 4):
            raise ValueError(f"true_rows must have shape (M, 3) or (M, 4), got {rows.shape}")
        ids = [int(i) for i in np.asarray(ids).reshape(-1).tolist()]
        if len(ids) != rows.shape[0] or len(set(ids)) != len(ids):
            raise ValueError("one distinct id per row is needed")
        if not self.config.enabled:
            if rows.shape[1] == 4:
                return rows
            out = np.zeros((rows.shape[0], 4))
            out[:, :3] = rows
            return out
        if self._rng is None:
            raise RuntimeError("call reset(rng) before measure")
        return self._measure(rows[:, :3], ids)

    def _measure(self, rows: np.ndarray, ids: list[int]) -> np.ndarray:
        cfg = self.config
        m = rows.shape[0]
        fresh = self._rng.standard_normal((m, 3))  # one draw per row and component, in row order
        gain = math.sqrt(max(1.0 - self.phi * self.phi, 0.0))
        new = _empty_tracks(m, int(cfg.latency_steps) + 1)
        out = np.empty((m, 4))
        _measure_rows(np.ascontiguousarray(rows), np.array(ids, dtype=np.int64), fresh, self._tracks,
                      (cfg.sigma_s, cfg.sigma_n, cfg.sigma_v, self.phi, gain),
                      (self.length, self.dt, cfg.jump_distance, cfg.tracker_alpha, cfg.tracker_beta,
                       bool(cfg.latency_compensation)), new, out)
        self._tracks = new
        return out


def _empty_tracks(m: int, depth: int) -> tuple:
    """Track state of ``m`` identities with delay lines of ``depth`` entries, the bundle of :func:`_measure_rows`
    (``old``, ``new``): identity, noise (3), delay line (depth, 3), its length and its oldest entry, whether
    the tracker has started, its offset and rate estimates, the last true arc length."""
    return (np.zeros(m, dtype=np.int64), np.zeros((m, 3)), np.zeros((m, depth, 3)), np.zeros(m, dtype=np.int64),
            np.zeros(m, dtype=np.int64), np.zeros(m, dtype=np.bool_), np.zeros(m), np.zeros(m), np.zeros(m))


@kernel
def _measure_rows(rows, ids, fresh, old, noise_model, tracker, new, out):
    """One measurement of the rows ``(s, n, v)`` of the identities ``ids`` (module docstring): the tracks of the
    previous call (``old``, a bundle of :func:`_empty_tracks`) carried over by identity, restarted for a new
    identity or after a jump; writes the tracks of this call (``new``, the same bundle) and the sensed rows ``out``
    (M, 4). ``fresh`` (M, 3): the standard normal draws; ``noise_model``: ``(sigma_s, sigma_n, sigma_v, phi,
    gain)``; ``tracker``: ``(length, dt, jump_distance, alpha, beta, compensate)``. The operations of the
    Python-float form it replaced, in its order."""
    old_ids, old_noise, old_delay, old_count, old_head, old_started, old_n_hat, old_rate, old_last_s = old
    sigma_s, sigma_n, sigma_v, phi, gain = noise_model
    length, dt, jump_distance, alpha, beta, compensate = tracker
    ids_out, noise, delay, count, head, started, n_hat, n_dot_hat, last_s = new
    depth = delay.shape[1]
    sig = (sigma_s, sigma_n, sigma_v)
    L = length
    for k in range(rows.shape[0]):
        s_true = rows[k, 0]
        ids_out[k] = ids[k]
        j = -1
        for q in range(old_ids.shape[0]):
            if old_ids[q] == ids[k]:
                j = q
                break
        if j >= 0 and abs((s_true - old_last_s[j] + 0.5 * L) % L - 0.5 * L) > jump_distance:
            j = -1
        if j < 0:  # a new track, its noise drawn from the stationary distribution
            for c in range(3):
                noise[k, c] = sig[c] * fresh[k, c]
            count[k] = head[k] = 0
            started[k] = False
            n_hat[k] = n_dot_hat[k] = 0.0
        else:
            for c in range(3):
                noise[k, c] = phi * old_noise[j, c] + gain * sig[c] * fresh[k, c]
            delay[k] = old_delay[j]
            count[k], head[k] = old_count[j], old_head[j]
            started[k], n_hat[k], n_dot_hat[k] = old_started[j], old_n_hat[j], old_rate[j]
        last_s[k] = s_true
        # the delay line: append the measurement, dropping the oldest once it holds `depth`
        s_z = (rows[k, 0] + noise[k, 0]) % L
        if count[k] < depth:
            slot = (head[k] + count[k]) % depth
            count[k] += 1
        else:
            slot = head[k]
            head[k] = (head[k] + 1) % depth
        delay[k, slot, 0] = 0.0 if s_z >= L else s_z
        delay[k, slot, 1] = rows[k, 1] + noise[k, 1]
        delay[k, slot, 2] = rows[k, 2] + noise[k, 2]
        oldest = head[k]
        s_seen, n_seen, v_seen = delay[k, oldest, 0], delay[k, oldest, 1], delay[k, oldest, 2]
        # one alpha-beta step on the delayed lateral measurement
        if not started[k]:
            started[k] = True
            n_hat[k], n_dot_hat[k] = n_seen, 0.0
            rate = 0.0
        else:
            predicted = n_hat[k] + dt * n_dot_hat[k]
            r = n_seen - predicted
            n_hat[k] = predicted + alpha * r
            n_dot_hat[k] = n_dot_hat[k] + beta / dt * r
            rate = n_dot_hat[k]
        age = (count[k] - 1) * dt
        if compensate and age > 0.0:
            s_now = (s_seen + v_seen * age) % L
            out[k, 0], out[k, 1] = (s_now if s_now < L else 0.0), n_seen + rate * age
        else:
            out[k, 0], out[k, 1] = s_seen, n_seen
        out[k, 2], out[k, 3] = v_seen, rate
