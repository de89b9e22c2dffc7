"""Planner inputs shared by the planning tests: a straight 12 m track and random instances."""

from __future__ import annotations

import numpy as np

from sofar_env.planning import MIQPConfig

CFG = MIQPConfig()
N = CFG.nodes
HALF_WIDTH = 6.0  # m, a 12 m wide track centred on the raceline


def straight(v: float = 50.0, half_width: float = HALF_WIDTH):
    """Node arc lengths at constant speed, zero reference, symmetric edges."""
    s = v * CFG.node_dt * np.arange(N)
    return s, np.zeros(N), -half_width * np.ones(N), half_width * np.ones(N)


def random_instance(rng: np.random.Generator, min_gap: float = 10.0):
    v = rng.uniform(40.0, 60.0)
    t = CFG.node_dt * np.arange(N)
    s = v * t
    shift = rng.uniform(-2.0, 2.0)
    n_min = -HALF_WIDTH + shift + 0.5 * np.sin(s / 80.0)
    n_max = n_min + 12.0
    n_ref = 0.8 * np.sin(s / 60.0 + rng.uniform(0, 6))
    M = int(rng.integers(1, 5))
    opp = np.column_stack([rng.uniform(min_gap, 120.0, M), rng.uniform(-3.5, 3.5, M),
                           v * rng.uniform(0.75, 0.97, M)])
    return s, n_ref, n_min, n_max, float(rng.uniform(-1.0, 1.0)), opp
