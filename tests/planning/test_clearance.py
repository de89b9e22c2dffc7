"""Tests of the side-constraint windows and clusters of the MIQP (sofar_env.planning.clearance)."""

from __future__ import annotations

import numpy as np
import pytest

from sofar_env.planning import MIQPConfig
from sofar_env.planning.clearance import ClearanceWindow, side_clusters

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


@pytest.mark.parametrize("closing_decel, stride", [(0.0, 3), (10.0, 1), (10.0, 3), (4.0, 2)])
def test_clearance_matches_the_direct_form_exactly(closing_decel, stride):
    cfg = MIQPConfig(closing_decel=closing_decel, closing_stride=stride)
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
def test_closing_speed_is_minus_the_numpy_gradient(node_dt):
    window = ClearanceWindow(MIQPConfig(closing_decel=10.0, node_dt=node_dt))
    f = np.random.default_rng(3).normal(size=(5, window.config.nodes)) * 50.0
    f[0] = 3.0  # a constant row (zero derivative)
    np.testing.assert_array_equal(window.t, node_dt * np.arange(window.config.nodes))
    # minus numpy's gradient; a zero derivative may come out as -0.0 or 0.0
    np.testing.assert_array_equal(np.abs(window.closing_speed(f)), np.abs(np.gradient(f, window.t, axis=1)))
    np.testing.assert_array_equal(window.closing_speed(f)[1:], -np.gradient(f, window.t, axis=1)[1:])


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
