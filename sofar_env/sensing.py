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
from collections import deque
from dataclasses import dataclass

import numpy as np

__all__ = ["SensorConfig", "Sensor"]


@dataclass(frozen=True)
class SensorConfig:
    """Sensor model of the opponents (off by default: perfect sensing)."""

    enabled: bool = False
    """Apply the model; otherwise the true rows are returned unchanged and no random number is drawn."""
    sigma_s: float = 1.0
    """Standard deviation of the arc-length error [m], >= 0."""
    sigma_n: float = 0.3
    """Standard deviation of the lateral-offset error [m], >= 0."""
    sigma_v: float = 0.5
    """Standard deviation of the speed error [m/s], >= 0."""
    correlation_time: float = 0.3
    """Correlation time tau of the Gauss-Markov errors [s], > 0."""
    latency_steps: int = 2
    """Delay of the output in control steps [-], >= 0."""
    tracker_alpha: float = 0.3
    """Position gain of the alpha-beta tracker of the lateral offset [-], in (0, 1]."""
    tracker_beta: float = 0.05
    """Rate gain of the alpha-beta tracker [-], in (0, 2). With alpha 0.3 at 0.1 s steps: a constant
    lateral rate is picked up within about 2 s, and the default noise leaves a rate error of about
    0.33 m/s (std); higher gains react faster and are noisier (0.5 / 0.1: 1.5 s, 0.44 m/s)."""
    jump_distance: float = 50.0
    """A true arc-length change above this between two calls restarts the identity's track [m], > 0."""
    latency_compensation: bool = True
    """Carry the delayed measurement forward over its age at the measured speed and lateral rate
    (``s + v * age``, ``n + n_dot * age``); off, the output is the raw delayed measurement."""

    def __post_init__(self) -> None:
        values = (self.sigma_s, self.sigma_n, self.sigma_v, self.correlation_time, self.tracker_alpha,
                  self.tracker_beta, self.jump_distance)
        if not all(math.isfinite(x) for x in values):
            raise ValueError("sensor settings must be finite")
        if min(self.sigma_s, self.sigma_n, self.sigma_v) < 0.0:
            raise ValueError("sensor standard deviations must be >= 0")
        if self.correlation_time <= 0.0 or self.jump_distance <= 0.0:
            raise ValueError("correlation_time and jump_distance must be positive")
        if int(self.latency_steps) != self.latency_steps or self.latency_steps < 0:
            raise ValueError(f"latency_steps must be an integer >= 0, got {self.latency_steps}")
        if not (0.0 < self.tracker_alpha <= 1.0 and 0.0 < self.tracker_beta < 2.0):
            raise ValueError("tracker gains must satisfy 0 < alpha <= 1 and 0 < beta < 2")

    @property
    def sigmas(self) -> np.ndarray:
        return np.array([self.sigma_s, self.sigma_n, self.sigma_v])


class _Track:
    """Sensor state of one identity: noise, delay line, tracker."""

    __slots__ = ("noise", "delay", "n_hat", "n_dot_hat", "last_s")

    def __init__(self, noise: tuple[float, float, float], latency: int, s: float):
        self.noise = noise
        self.delay: deque = deque(maxlen=latency + 1)
        self.n_hat: float | None = None
        self.n_dot_hat = 0.0
        self.last_s = s


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
        self._tracks: dict[int, _Track] = {}

    def reset(self, rng: np.random.Generator | None = None) -> None:
        """Forget every track; when enabled, seed the sensor's own generator from ``rng`` (one draw)."""
        self._tracks = {}
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
        # on Python floats (the per-component numpy operations on 3-vectors, in the same order: the same bits)
        cfg, L, phi, dt = self.config, self.length, self.phi, self.dt
        sig = (cfg.sigma_s, cfg.sigma_n, cfg.sigma_v)
        m = rows.shape[0]
        fresh = self._rng.standard_normal((m, 3)).tolist()  # one draw per row and component, in row order
        gain = math.sqrt(max(1.0 - phi * phi, 0.0))
        tracks, out = {}, []
        for key, row, f in zip(ids, rows.tolist(), fresh):
            s_true = row[0]
            tr = self._tracks.get(key)
            if tr is None or abs((s_true - tr.last_s + 0.5 * L) % L - 0.5 * L) > cfg.jump_distance:
                tr = _Track(tuple(sj * fj for sj, fj in zip(sig, f)), cfg.latency_steps, s_true)  # stationary start
            else:
                tr.noise = tuple(phi * nj + gain * sj * fj for nj, sj, fj in zip(tr.noise, sig, f))
            tr.last_s = s_true
            s_z = (row[0] + tr.noise[0]) % L
            tr.delay.append((0.0 if s_z >= L else s_z, row[1] + tr.noise[1], row[2] + tr.noise[2]))
            s_seen, n_seen, v_seen = tr.delay[0]  # latency_steps old once the delay line is full, else the first
            rate = self._track_rate(tr, n_seen)
            age = (len(tr.delay) - 1) * dt
            if cfg.latency_compensation and age > 0.0:
                s_now = (s_seen + v_seen * age) % L
                out.append((s_now if s_now < L else 0.0, n_seen + rate * age, v_seen, rate))
            else:
                out.append((s_seen, n_seen, v_seen, rate))
            tracks[key] = tr
        self._tracks = tracks
        return np.array(out, dtype=float).reshape(m, 4)

    def _track_rate(self, tr: _Track, n_meas: float) -> float:
        """One alpha-beta step on the (delayed) lateral measurement; returns the rate estimate [m/s]."""
        if tr.n_hat is None:
            tr.n_hat, tr.n_dot_hat = n_meas, 0.0
            return 0.0
        a, b, dt = self.config.tracker_alpha, self.config.tracker_beta, self.dt
        predicted = tr.n_hat + dt * tr.n_dot_hat
        r = n_meas - predicted
        tr.n_hat = predicted + a * r
        tr.n_dot_hat += b / dt * r
        return tr.n_dot_hat
