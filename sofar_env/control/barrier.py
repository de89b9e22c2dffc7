"""Velocity-aware elliptic barrier between the ego car and one opponent.

The safe set of the paper (eq. "velocity-aware collision avoidance") is the zero
super-level set of

    h = (ds / a)^2 + (dn / b)^2 - 1,
    a = a0 + softplus(v_close)^2 / (2 a_brake),

with ``ds = s_o - s`` the arc-length gap to the opponent (> 0 when it is ahead),
``dn = n_o - n`` the lateral offset between the two reference points and ``v_close``
the closing speed. The function is written **once** over an ``ops`` namespace, so
the numeric version (:func:`barrier`, vectorised numpy) and the symbolic one
(:func:`casadi_barrier`, used by the MPC) cannot drift apart.

Choices and why
---------------
* **Containment of the collision set.** Collision in the world is a test between
  two oriented 4.9 m x 1.9 m rectangles whose centre is the reference point. With
  aligned headings the cars touch exactly when the centres are inside the Minkowski
  sum, the rectangle ``|ds| <= 4.9 m, |dn| <= 1.9 m``. Its corner satisfies
  ``(4.9 / 7.0)^2 + (1.9 / 2.7)^2 = 0.985 < 1``, so with the defaults ``a0 = 7.0 m``
  and ``b = 2.7 m`` the whole rectangle lies in ``{h < 0}`` even at zero closing
  speed; ``h >= 0`` therefore certifies "no contact" for aligned cars. There is no
  extra additive margin constant (the authors' reference code subtracts ``1 + 0.5``); the
  margin is in the semi-axes, where it has a geometric meaning.
* **Braking distance.** ``a`` grows with the square of the closing speed over twice
  the braking capability ``a_brake = 10 m/s^2`` (the AV-21's strongest braking), so
  the ellipse ahead is as long as the distance needed to cancel the closing speed.
* **The relevant closing speed.** For an opponent ahead it is ``v - v_o``, for one
  behind ``v_o - v``. Both are captured smoothly by
  ``v_close = (v - v_o) * tanh(ds / sigma)`` with ``sigma = 2 m``; near ``ds = 0``
  (cars side by side), where the sign is ambiguous, ``(ds / a)^2`` is about zero
  anyway, so the blend costs nothing.
* **Heading (an option, off by default).** The containment above holds for cars aligned with the
  track. A car turned by e reaches ``(length / 2) |sin e|`` further across it (about 0.95 m more at
  0.4 rad), which happens in slow corners and chicanes. ``heading_extent`` widens ``b`` by that much
  times a smooth ``|sin e|`` of the ego's own heading error, plus as much for the opponent's rotation
  where the controller knows it: ``sin_course_o``, the sine of the opponent's course angle to the track
  (its lateral rate over its speed, ``n_dot / v``), 0 where unknown. That is what the end of a car
  facing the other one needs when it swings towards it; a car well behind another and turned *away*
  from it reaches no closer with its front end. ``heading_sides = "toward"`` widens by the ego's turn
  only as far as the facing end swings towards the opponent, and by every turn alongside
  (:func:`_toward`); ``"both"`` (the default) by every turn everywhere.
* **Smooth max.** ``max(0, v_close)`` is replaced by the softplus
  ``softplus_k(x) = log(1 + exp(k x)) / k`` with sharpness ``k = 4 s/m``. It is an
  upper bound of ``max(0, x)`` (so the ellipse only gets longer), differs from it by
  at most ``log(2) / k = 0.17 m/s`` (at ``x = 0``: 0.0015 m of semi-axis), and is
  evaluated in the overflow-free form ``(x + |x|) / 2 + log1p(exp(-k |x|)) / k``,
  whose derivative is exact everywhere, also at ``x = 0``.
"""

from __future__ import annotations

import math

from types import SimpleNamespace
from typing import Any

import numpy as np

from .._jit import kernel, minimum
from ..configs.mpc import BarrierParams

__all__ = ["BarrierParams", "barrier_expr", "barrier", "barrier_table", "casadi_barrier", "casadi_ops", "min_barrier",
           "semi_axis_s", "softplus"]




_NUMPY_OPS = SimpleNamespace(abs=np.abs, exp=np.exp, log1p=np.log1p, tanh=np.tanh, sin=np.sin, sqrt=np.sqrt)
_MATH_OPS = SimpleNamespace(abs=abs, exp=math.exp, log1p=math.log1p, tanh=math.tanh, sin=math.sin, sqrt=math.sqrt)
_HEADING_EPS = 0.01
_SIDE_SCALE = 0.5
"""Lateral scale [m] of the smooth side ``tanh(dn / _SIDE_SCALE)`` of ``heading_sides = "toward"``: 0.96 of the
full side at 1 m, where ``(dn / b)^2`` starts to matter."""


def casadi_ops() -> SimpleNamespace:
    """The ``ops`` namespace of CasADi (``abs``, ``exp``, ``log1p``, ``tanh``) for :func:`barrier_expr`."""
    import casadi as ca

    return SimpleNamespace(abs=ca.fabs, exp=ca.exp, log1p=ca.log1p, tanh=ca.tanh, sin=ca.sin, sqrt=ca.sqrt)


def softplus(x: Any, k: float, ops: Any = _NUMPY_OPS) -> Any:
    """Smooth upper bound of max(0, x) with sharpness ``k``, overflow-free."""
    return 0.5 * (x + ops.abs(x)) + ops.log1p(ops.exp(-k * ops.abs(x))) / k


def semi_axis_s(ds: Any, v: Any, v_o: Any, p: BarrierParams, ops: Any = _NUMPY_OPS) -> Any:
    """Longitudinal semi-axis a [m] for gap ``ds`` [m], ego speed ``v`` and opponent speed ``v_o`` [m/s]."""
    v_close = (v - v_o) * ops.tanh(ds / p.sigma)
    sp = softplus(v_close, p.sharpness, ops)
    return p.a0 + sp * sp / (2.0 * p.a_brake)


def barrier_expr(s: Any, n: Any, v: Any, s_o: Any, n_o: Any, v_o: Any, p: BarrierParams,
                 ops: Any = _NUMPY_OPS, e: Any = 0.0, sin_course_o: Any = 0.0) -> Any:
    """h for ego (s, n, v) against an opponent (s_o, n_o, v_o), over the ``ops`` namespace; ``e`` is the
    ego's heading error [rad] and ``sin_course_o`` the sine of the opponent's course angle to the track
    [-] (0: aligned or unknown), both used only with ``p.heading_extent`` > 0.

    Units: s, n, s_o, n_o in m; v, v_o in m/s. h is dimensionless, >= 0 is safe.
    """
    ds = s_o - s
    dn = n_o - n
    a = semi_axis_s(ds, v, v_o, p, ops)
    if p.heading_extent == 0.0:  # the aligned ellipse, the very same expression as without the option
        return (ds / a) ** 2 + (dn / p.b) ** 2 - 1.0
    sin_e = ops.sin(e)
    eps2 = _HEADING_EPS ** 2
    if p.heading_sides == "both":
        turned = ops.sqrt(sin_e * sin_e + eps2) + ops.sqrt(sin_course_o * sin_course_o + eps2) - 2.0 * _HEADING_EPS
    else:
        turned = _toward(ds, dn, sin_e, p.heading_extent, ops) + ops.sqrt(sin_course_o * sin_course_o + eps2) \
            - _HEADING_EPS
    b = p.b + p.heading_extent * turned
    return (ds / a) ** 2 + (dn / b) ** 2 - 1.0


def _toward(ds: Any, dn: Any, sin_e: Any, length: float, ops: Any = _NUMPY_OPS) -> Any:
    """The ego's share of the widening with ``BarrierParams.heading_sides = "toward"`` [-].

    ``end = tanh(ds / length)`` is +1 with the opponent well ahead (the ego's front end faces it), -1 well
    behind (the rear end does); ``side = tanh(dn / _SIDE_SCALE)`` the side the opponent is on. The end facing
    the opponent swings towards it by ``length * sin(e) * side * end`` when that is > 0, and away otherwise,
    so far from alongside the share is the smooth ``max(0, sin(e) * side * end)``. Alongside, a turn in either
    direction brings one end closer (an end behind the opponent's near end, or the side between), so the
    share blends to ``"both"``'s ``|sin e|_eps`` with weight ``1 - end^2``. With ``length`` half the car's
    length that weight covers what a turned-away car needs: its side reaches ``(length - |ds|) |sin e|``
    closer at ``|ds| < length``, and ``length (1 - tanh^2(ds / length)) |sin e|`` is at least that. The
    smooth max is ``(x + |x|_eps) / 2``, within ``_HEADING_EPS / 2`` below 0 for x < 0."""
    eps = _HEADING_EPS
    end = ops.tanh(ds / length)
    side = ops.tanh(dn / _SIDE_SCALE)
    x = sin_e * side * end
    both = ops.sqrt(sin_e * sin_e + eps * eps) - eps
    return (1.0 - end * end) * both + end * end * 0.5 * (x + ops.sqrt(x * x + eps * eps) - eps)


def barrier(ego: Any, opponents: Any, p: BarrierParams = BarrierParams()) -> np.ndarray:
    """Numeric h, vectorised with numpy broadcasting.

    ``ego`` is ``(..., 3)`` rows ``(s, n, v)`` or a full Frenet state ``(..., 5)``
    ``(s, n, e, v, delta)``; ``opponents`` is ``(..., 3)`` rows ``(s, n, v)`` or ``(..., 4)`` rows
    ``(s, n, v, sin_course)`` (see :func:`barrier_expr`). The
    leading dimensions broadcast, e.g. ``barrier(x[None, :], opps)`` gives one value
    per opponent.
    """
    ego = np.asarray(ego, dtype=float)
    opponents = np.asarray(opponents, dtype=float)
    if ego.shape[-1] == 5:
        s, n, v, e = ego[..., 0], ego[..., 1], ego[..., 3], ego[..., 2]
    elif ego.shape[-1] == 3:
        s, n, v, e = ego[..., 0], ego[..., 1], ego[..., 2], 0.0
    else:
        raise ValueError(f"ego must end in 3 (s, n, v) or 5 (s, n, e, v, delta) values, got shape {ego.shape}")
    if opponents.shape[-1] not in (3, 4):
        raise ValueError(f"opponents must end in 3 values (s, n, v) or 4 (s, n, v, sin_course), got shape "
                         f"{opponents.shape}")
    course = opponents[..., 3] if opponents.shape[-1] == 4 else 0.0
    return barrier_expr(s, n, v, opponents[..., 0], opponents[..., 1], opponents[..., 2], p, _NUMPY_OPS, e, course)


def barrier_table(xs: np.ndarray, opponents: np.ndarray, p: BarrierParams) -> tuple[np.ndarray, np.ndarray, float]:
    """h of the ego states ``xs`` (K, 5) against M opponents: ``(h (K, M), h.min(axis=0) (M,), h.min())``.

    ``opponents`` is (K, M, 3 or 4), row k the opponents at the time of ``xs[k]``, or (1, M, 3 or 4), the
    same opponents for every state; the values are those of ``barrier(xs[:, None, :], opponents, p)``
    to the bit. K and M must be >= 1. Without ``heading_extent`` the arithmetic runs in three compiled
    calls (:mod:`sofar_env._jit`) around numpy's tanh, exp and log1p, applied to the very arrays
    :func:`barrier_expr` applies them to (so the same SIMD loops); with it, through :func:`barrier`.
    """
    if p.heading_extent != 0.0:
        h = barrier(xs[:, None, :], opponents, p)
        hk = h.min(axis=0)
        return h, hk, float(hk.min())
    w = _table_gaps(xs, opponents, p.sigma)
    np.tanh(w[3], out=w[3])
    _table_close(w, p.sharpness)
    np.exp(w[3], out=w[3])
    np.log1p(w[3], out=w[3])
    return _table_finish(w, p.sharpness, p.a0, p.a_brake, p.b)


@kernel
def _table_gaps(xs, o, sigma):
    """(4, K, M) work array of :func:`barrier_table`: ds, dn, v - v_o, ds / sigma."""
    n_k, n_m = xs.shape[0], o.shape[1]
    w = np.empty((4, n_k, n_m))
    for k in range(n_k):
        j = k if o.shape[0] > 1 else 0
        for i in range(n_m):
            ds = o[j, i, 0] - xs[k, 0]
            w[0, k, i] = ds
            w[1, k, i] = o[j, i, 1] - xs[k, 1]
            w[2, k, i] = xs[k, 3] - o[j, i, 2]
            w[3, k, i] = ds / sigma
    return w


@kernel
def _table_close(w, k):
    """``w[2]``: the closing speed (v - v_o) tanh(ds / sigma) (w[3] holds the tanh); ``w[3]``: -k |that|."""
    for a in range(w.shape[1]):
        for i in range(w.shape[2]):
            vc = w[2, a, i] * w[3, a, i]
            w[2, a, i] = vc
            w[3, a, i] = -k * abs(vc)


@kernel
def _table_finish(w, k, a0, a_brake, b):
    """h from the closing speed ``w[2]`` and log1p(exp(-k |v_close|)) in ``w[3]`` (:func:`barrier_expr`)."""
    n_k, n_m = w.shape[1], w.shape[2]
    h = np.empty((n_k, n_m))
    hk = np.empty(n_m)
    hmin = np.inf
    for a in range(n_k):
        for i in range(n_m):
            vc = w[2, a, i]
            sp = 0.5 * (vc + abs(vc)) + w[3, a, i] / k
            ax = a0 + sp * sp / (2.0 * a_brake)
            r = w[0, a, i] / ax
            q = w[1, a, i] / b
            v = r * r + q * q - 1.0
            h[a, i] = v
            hk[i] = v if a == 0 else minimum(hk[i], v)
            hmin = v if (a == 0 and i == 0) else minimum(hmin, v)
    return h, hk, hmin


def casadi_barrier(p: BarrierParams = BarrierParams()):
    """CasADi function ``h(x[5], o[3]) -> h``: ego Frenet state, opponent ``(s, n, v)``."""
    import casadi as ca

    x = ca.SX.sym("x", 5)
    o = ca.SX.sym("o", 3)
    h = barrier_expr(x[0], x[1], x[3], o[0], o[1], o[2], p, casadi_ops(), x[2])
    return ca.Function("barrier", [x, o], [h], ["x", "o"], ["h"])


def min_barrier(track, ego_frenet: np.ndarray, opponents: np.ndarray, params: BarrierParams) -> float:
    """Smallest barrier value h of the ego (s, n, e, v, delta) against the opponent rows (s, n, v[, ...]) now;
    inf without opponents.

    :func:`barrier_expr` on Python floats (the field is small), with s taken relative to the ego, written
    out inline: the same operations in the same order and the same libm calls (``math``; ``** 2`` stays
    Python's float power), without the per-opponent calls through the ``ops`` namespace.
    """
    s, n, v, e = float(ego_frenet[0]), float(ego_frenet[1]), float(ego_frenet[3]), float(ego_frenet[2])
    p = params
    k, sigma, a0, two_brake = p.sharpness, p.sigma, p.a0, 2.0 * p.a_brake
    toward = p.heading_extent != 0.0 and p.heading_sides == "toward"
    if p.heading_extent == 0.0:
        b = p.b
    else:  # sin_course_o = 0.0, as barrier_expr's default
        sin_e = math.sin(e)
        eps2 = _HEADING_EPS ** 2
        b = p.b + p.heading_extent * (math.sqrt(sin_e * sin_e + eps2) + math.sqrt(0.0 * 0.0 + eps2) - 2.0 * _HEADING_EPS)
    h = math.inf
    for row in np.asarray(opponents, float).tolist():
        ds = track.gap(row[0], s) - 0.0
        dn = row[1] - n
        if toward:  # the widening depends on where the opponent is (_toward)
            b = p.b + p.heading_extent * (_toward(ds, dn, sin_e, p.heading_extent, _MATH_OPS)
                                          + math.sqrt(0.0 * 0.0 + eps2) - _HEADING_EPS)
        x = (v - row[2]) * math.tanh(ds / sigma)
        ax = abs(x)
        sp = 0.5 * (x + ax) + math.log1p(math.exp(-k * ax)) / k
        a = a0 + sp * sp / two_brake
        h = min(h, (ds / a) ** 2 + (dn / b) ** 2 - 1.0)
    return h
