"""The compiled side clustering and side hysteresis against the Python forms they replaced, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from sofar_env.planning import MIQPConfig
from sofar_env.planning.clearance import side_clusters
from sofar_env.planning.hysteresis import match_previous_sides


def _clusters_reference(pos, act_rel, cluster_gap, apart=None):
    """The numpy and Python form of side_clusters before it was compiled."""
    R = pos.shape[0]
    if R == 1:
        return 1, np.zeros(1, dtype=int)
    close = np.abs(pos[:, None, :] - pos[None, :, :]) < cluster_gap
    either = act_rel[:, None, :] | act_rel[None, :, :]
    linked = (close & either).any(axis=2)
    if apart is not None:
        linked &= ~apart
    linked = linked.tolist()
    labels = [-1] * R
    n = 0
    for i in range(R):
        if labels[i] >= 0:
            continue
        labels[i] = n
        stack = [i]
        while stack:
            j = stack.pop()
            for k in range(R):
                if labels[k] < 0 and linked[j][k]:
                    labels[k] = n
                    stack.append(k)
        n += 1
    return n, np.asarray(labels, dtype=int)


def _match_reference(config, s_nodes, progress, opp_rel, prev_opp, prev_sides):
    """The Python form of match_previous_sides before it was compiled."""
    out = np.full(opp_rel.shape[0], -1)
    if prev_sides is None or prev_opp is None:
        return out
    had_side = prev_sides != 0
    if not had_side.any():
        return out
    prev = prev_opp[had_side].tolist()
    prev_side = prev_sides[had_side].tolist()
    v_ego = float(s_nodes[1] - s_nodes[0]) / config.node_dt
    progress = float(progress)
    dt = progress / v_ego if v_ego > 0.1 and progress > 0.0 else 0.0
    s_pred = [row[0] + row[2] * dt - progress for row in prev]
    gap_scale = config.cluster_gap
    if not gap_scale > 0.0:
        return out
    lat_scale = max(config.safe_lat, 1e-9)
    for r, (s_r, n_r) in enumerate(opp_rel[:, :2].tolist()):
        best, best_j = np.inf, -1
        for j, row in enumerate(prev):
            ds = abs(s_r - s_pred[j]) / gap_scale
            dn = abs(n_r - row[1]) / lat_scale
            if ds < 1.0 and dn < 1.0 and ds + dn < best:
                best, best_j = ds + dn, j
        if best_j >= 0:
            out[r] = 1 if prev_side[best_j] > 0 else 0
    return out


@pytest.mark.parametrize("seed", range(6))
def test_side_clusters_are_those_of_the_python_form(seed):
    rng = np.random.default_rng(seed)
    checked = 0
    for _ in range(150):
        R, N = int(rng.integers(1, 7)), int(rng.integers(2, 12))
        # cars a few metres apart along the track, converging and diverging over the nodes
        pos = rng.uniform(0.0, 40.0, (R, 1)) + rng.normal(0.0, 4.0, (R, N)).cumsum(axis=1)
        if rng.random() < 0.2:
            pos[rng.integers(R), rng.integers(N)] = np.nan
        act = rng.random((R, N)) < 0.4
        apart = None
        if rng.random() < 0.5:
            apart = rng.random((R, R)) < 0.3
            apart = apart | apart.T
        gap = float(rng.choice([0.0, 4.0, 10.0, 25.0]))
        n, labels = side_clusters(pos, act, gap, apart)
        n_ref, labels_ref = _clusters_reference(pos, act, gap, apart)
        assert n == n_ref and type(n) is int
        np.testing.assert_array_equal(labels, labels_ref)
        assert labels.dtype == labels_ref.dtype
        checked += n < R  # some cars linked
    assert checked > 20  # the tables exercise the search, not only singletons


@pytest.mark.parametrize("seed", range(6))
def test_previous_sides_are_those_of_the_python_form(seed):
    rng = np.random.default_rng(seed)
    configs = (MIQPConfig(), MIQPConfig(cluster_gap=4.0, safe_lat=0.3), MIQPConfig(safe_lat=0.0),
               MIQPConfig(cluster_gap=0.0))
    matched = 0
    for _ in range(150):
        cfg = configs[int(rng.integers(len(configs)))]
        v = float(rng.choice([0.0, 0.05, 30.0, 60.0]))
        s_nodes = v * np.arange(cfg.nodes) * cfg.node_dt
        progress = float(rng.choice([0.0, -1.0, rng.uniform(0.0, 8.0)]))
        Mp, R = int(rng.integers(0, 5)), int(rng.integers(0, 5))
        prev_opp = np.column_stack([rng.uniform(-20, 120, Mp), rng.uniform(-3, 3, Mp), rng.uniform(20, 60, Mp)])
        prev_sides = rng.integers(-1, 2, Mp)
        # current cars near where the previous ones went, or anywhere
        near = prev_opp[rng.integers(0, max(Mp, 1), R)] if Mp else np.zeros((R, 3))
        opp = near + rng.normal(0.0, [3.0, 0.4, 1.0], (R, 3))
        if R and rng.random() < 0.2:
            opp[0, 0] = np.nan
        for prev in ((prev_opp, prev_sides), (None, None)):
            got = match_previous_sides(cfg, s_nodes, progress, opp, *prev)
            want = _match_reference(cfg, s_nodes, progress, opp, *prev)
            np.testing.assert_array_equal(got, want)
            assert got.dtype == want.dtype and got.shape == (R,)
            matched += int((got >= 0).sum())
    assert matched > 20  # the tables exercise the matching, not only its early returns
