"""Tests of the side-constraint windows and clusters of the MIQP (sofar_env.planning.clearance)."""

from __future__ import annotations

import numpy as np
import pytest

from sofar_env.planning import MIQPConfig
from sofar_env.planning.clearance import ClearanceWindow, ellipse_violation, side_clusters

from .instances import CFG, N


# --------------------------------------------------------------------------
# The vectorised clearance window against a direct (per-row, per-node) form.
# --------------------------------------------------------------------------
def reference_clearance(cfg: MIQPConfig, t: np.ndarray, s_nodes: np.ndarray, opp_s: np.ndarray) -> np.ndarray:
    """The clearance window of the module docstring, written out row by row."""
    L = cfg.safe_lon
    gap = opp_s - s_nodes[None, :]
    if cfg.closing_decel > 0.0:
        dv = -np.gradient(gap, t, axis=1)
        ext_ahead = np.maximum(dv, 0.0) ** 2 / (2.0 * cfg.closing_decel)
        ext_behind = np.maximum(-dv, 0.0) ** 2 / (2.0 * cfg.closing_decel)
    else:
        ext_ahead = ext_behind = np.zeros_like(gap)

    def required(g, e_ahead, e_behind):
        ext = np.where(g > 0.0, e_ahead, e_behind)
        if cfg.window_shape == "ellipse":  # safe_lat sqrt(1 - (g / A)^2) inside, A = safe_lon + ext
            r = g / (L + ext)
            return cfg.safe_lat * np.sqrt(np.maximum(1.0 - r * r, 0.0))
        a = np.abs(g)
        out = np.where(a < L, cfg.safe_lat, 0.0)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            r = (a - L) / ext
            cap = cfg.safe_lat * np.sqrt(np.clip(1.0 - r * r, 0.0, 1.0))
        return np.where((a >= L) & (ext > 0.0) & (a - L < ext), cap, out)

    w = required(gap, ext_ahead, ext_behind)
    a, b = gap[:, :-1], gap[:, 1:]
    g_near = np.where((a > 0.0) & (b > 0.0), np.minimum(a, b),
                      np.where((a < 0.0) & (b < 0.0), np.maximum(a, b), 0.0))
    seg = required(g_near, np.maximum(ext_ahead[:, :-1], ext_ahead[:, 1:]),
                   np.maximum(ext_behind[:, :-1], ext_behind[:, 1:]))
    w[:, :-1] = np.maximum(w[:, :-1], seg)
    w[:, 1:] = np.maximum(w[:, 1:], seg)
    stride = int(cfg.closing_stride)
    if stride > 1 and cfg.closing_decel > 0.0:
        box = np.abs(gap) < L
        out = w.copy()
        k = np.arange(w.shape[1])
        for i in range(w.shape[0]):
            bk = np.flatnonzero(box[i])
            if bk.size == 0:
                bk = np.array([int(np.argmax(w[i]))])
            dist = np.abs(k[:, None] - bk[None, :]).min(axis=1)
            drop = (w[i] > 0.0) & ~box[i] & (dist > 1) & ((dist - 1) % stride != 0)
            out[i, drop] = 0.0
        w = out
    return w


@pytest.mark.parametrize("closing_decel, stride, shape", [(0.0, 3, "box"), (10.0, 1, "box"), (10.0, 3, "box"),
                                                          (4.0, 2, "box"), (0.0, 3, "ellipse"),
                                                          (10.0, 1, "ellipse"), (10.0, 3, "ellipse")])
def test_clearance_matches_the_direct_form_exactly(closing_decel, stride, shape):
    cfg = MIQPConfig(closing_decel=closing_decel, closing_stride=stride, window_shape=shape)
    window = ClearanceWindow(cfg)
    rng = np.random.default_rng(3)
    t = CFG.node_dt * np.arange(N)
    for _ in range(200):
        v = rng.uniform(20.0, 70.0)
        s_nodes = v * t + 0.5 * rng.uniform(-4.0, 2.0) * t ** 2
        s_nodes = np.maximum.accumulate(np.maximum(s_nodes, 0.0))
        M = int(rng.integers(0, 6))
        s0 = rng.uniform(-40.0, 400.0, M)  # includes far opponents (skipped rows)
        vo = v * rng.uniform(0.3, 1.3, M)
        acc = rng.uniform(-5.0, 5.0, M)
        opp_s = s0[:, None] + vo[:, None] * t[None, :] + 0.5 * acc[:, None] * t[None, :] ** 2
        got = window.clearance(s_nodes, opp_s)
        np.testing.assert_array_equal(got, reference_clearance(cfg, t, s_nodes, opp_s))


@pytest.mark.parametrize("node_dt", [0.15, 0.125])
def test_clearance_matches_the_direct_form_on_both_gradient_grids(node_dt):
    """0.125 s nodes are exactly uniform (the kernel's two-point central difference), 0.15 s ones are
    not (numpy's three-coefficient formula): both give numpy's gradient, so the direct form's bits."""
    from sofar_env._gradient import GridGradient

    cfg = MIQPConfig(closing_decel=10.0, node_dt=node_dt, closing_stride=3)
    window = ClearanceWindow(cfg)
    np.testing.assert_array_equal(window.t, node_dt * np.arange(cfg.nodes))
    assert GridGradient(window.t).coefficients()[0] == (node_dt == 0.125)
    rng = np.random.default_rng(5)
    for _ in range(100):
        s_nodes = rng.uniform(20.0, 70.0) * window.t
        opp_s = rng.uniform(-30.0, 120.0, (3, 1)) + rng.uniform(10.0, 80.0, (3, 1)) * window.t[None, :]
        np.testing.assert_array_equal(window.clearance(s_nodes, opp_s),
                                      reference_clearance(cfg, window.t, s_nodes, opp_s))


def test_window_extends_ahead_of_an_approached_car_only():
    """The braking-distance extension: towards a slower car ahead the clearance tapers from
    safe_lat over v_close^2 / (2 closing_decel); for cars separating the window is the box."""
    cfg = MIQPConfig(closing_decel=10.0, closing_stride=1)
    window = ClearanceWindow(cfg)
    s_nodes = 50.0 * window.t
    ahead = 100.0 + 30.0 * window.t   # closing at 20 m/s: extension 20 m
    plain = ClearanceWindow(MIQPConfig()).clearance(s_nodes, ahead[None, :])[0]
    w = window.clearance(s_nodes, ahead[None, :])[0]
    gap = ahead - s_nodes
    assert np.all(w >= plain) and np.any(w > plain)
    assert np.all(w[gap >= cfg.safe_lon + 20.0 + 20.0 * cfg.node_dt] == 0.0)
    assert np.all(w <= cfg.safe_lat)
    away = 5.0 + 60.0 * window.t  # a faster car alongside, pulling away: no extension
    np.testing.assert_array_equal(window.clearance(s_nodes, away[None, :]),
                                  ClearanceWindow(MIQPConfig()).clearance(s_nodes, away[None, :]))


def test_elliptic_window_around_a_parked_car_has_the_barrier_shape():
    """A parked car passed at walking pace (closing extension < 0.1 m): the clearance at the nodes
    follows safe_lat sqrt(1 - (g / safe_lon)^2) (up to the node-interval coverage, which only raises it,
    by less than a node spacing of gap), is safe_lat next to the car and 0 beyond the semi-axis."""
    cfg = MIQPConfig(safe_lat=3.0, safe_lon=7.0, closing_decel=10.0, closing_stride=1, window_shape="ellipse")
    window = ClearanceWindow(cfg)
    s_nodes = 1.0 * window.t  # 1 m/s: nodes 0.15 m apart
    parked = np.full((1, N), 5.0)
    w = window.clearance(s_nodes, parked)[0]
    gap = 5.0 - s_nodes
    exact = 3.0 * np.sqrt(np.maximum(1.0 - (gap / 7.0) ** 2, 0.0))
    assert np.all(w >= exact - 1e-12)
    near = np.maximum(np.abs(gap) - 0.15, 0.0)
    assert np.all(w <= 3.0 * np.sqrt(np.maximum(1.0 - (near / 7.1) ** 2, 0.0)) + 1e-12)
    assert w[np.argmin(np.abs(gap))] == pytest.approx(3.0, abs=1e-3)
    assert np.all(w[gap < -7.2] == 0.0)
    box = ClearanceWindow(MIQPConfig(safe_lat=3.0, safe_lon=7.0)).clearance(s_nodes, parked)[0]
    assert np.all(w <= box)  # the box of the same extent asks for more everywhere


def test_ellipse_violation_is_the_missing_lateral_distance():
    """A straight plan past a parked car at a lateral distance: inside the barrier ellipse by b - distance
    (sampled where the gap is 0), 0 from b on; and the closing speed lengthens the ellipse ahead."""
    t = 0.15 * np.arange(40)
    s_nodes = 2.0 * t  # 2 m/s, nodes 0.3 m apart: a sample at gap 0 exactly (the car at 6 m)
    parked = np.full((1, t.size), 6.0)
    for offset, expected in [(0.0, 2.7), (1.0, 1.7), (2.7, 0.0), (3.5, 0.0)]:
        got = ellipse_violation(t, s_nodes, np.full(t.size, offset), parked, np.array([0.0]),
                                a0=7.0, b=2.7, a_brake=10.0)
        assert got[0] == pytest.approx(expected, abs=1e-9)
    # swinging out only 5 m before the car: inside a0 = 7 m already, not at 8 m
    d = np.where(6.0 - s_nodes > 5.0, 0.0, 2.7)
    assert ellipse_violation(t, s_nodes, d, parked, np.array([0.0]), 7.0, 2.7, 10.0)[0] > 0.5
    far = np.full((1, t.size), 20.0)  # the car 12.4-20 m ahead: outside the zero-speed ellipse ...
    assert ellipse_violation(t, s_nodes, np.zeros(t.size), far, np.array([0.0]), 7.0, 2.7, 10.0)[0] == 0.0
    fast = 15.0 * t  # ... but inside the braking-distance ellipse at 15 m/s (a = 7 + 11.25 m)
    assert ellipse_violation(t, fast, np.zeros(t.size), np.full((1, t.size), 20.0), np.array([0.0]),
                             7.0, 2.7, 10.0)[0] > 2.0
    assert ellipse_violation(t, s_nodes, np.zeros(t.size), np.zeros((0, t.size)), np.zeros(0),
                             7.0, 2.7, 10.0).shape == (0,)


def test_side_clusters_link_opponents_the_ego_cannot_thread():
    t = CFG.node_dt * np.arange(N)
    pos = np.array([50.0 + 40.0 * t, 55.0 + 40.0 * t, 200.0 + 40.0 * t])  # 5 m apart, and a far one
    act = np.zeros((3, N), dtype=bool)
    act[0, 10:14] = act[2, 40:44] = True
    n, labels = side_clusters(pos, act, cluster_gap=10.0)
    assert n == 2 and labels[0] == labels[1] != labels[2]
    n, labels = side_clusters(pos, act, cluster_gap=4.0)  # 5 m apart is not close any more
    assert n == 3 and len(set(labels.tolist())) == 3
    act[:] = False  # the ego overlaps neither of the close pair: no link
    act[2, 40:44] = True
    assert side_clusters(pos, act, cluster_gap=10.0)[0] == 3
    # linking is transitive: 0-1 and 1-2 close, 0-2 not
    chain = np.array([50.0 + 0 * t, 58.0 + 0 * t, 66.0 + 0 * t])
    n, labels = side_clusters(chain, np.ones((3, N), dtype=bool), cluster_gap=10.0)
    assert n == 1 and np.all(labels == 0)


def test_side_clusters_never_link_a_pair_marked_apart():
    t = CFG.node_dt * np.arange(N)
    pos = np.array([50.0 + 40.0 * t, 52.0 + 40.0 * t])
    act = np.ones((2, N), dtype=bool)
    assert side_clusters(pos, act, cluster_gap=10.0)[0] == 1
    apart = np.array([[False, True], [True, False]])
    n, labels = side_clusters(pos, act, cluster_gap=10.0, apart=apart)
    assert n == 2 and labels[0] != labels[1]
