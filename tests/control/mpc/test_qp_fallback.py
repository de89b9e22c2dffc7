"""``MPCConfig.qp_fallback``: DAQP solves the QPs PIQP fails on, off by default (and out of the configuration hash)."""

from __future__ import annotations

import copy
import dataclasses

import gymnasium as gym
import numpy as np
import pytest

import sofar_env  # noqa: F401  (registers the ids)
from sofar_env.config import make_env_config
from sofar_env.config_hash import config_hash
from sofar_env.control.mpc import MPCConfig, MPCDCBF, backends
from sofar_env.errors import ConfigError
from sofar_env.stack import stack_preset

from .scenarios import make_stage


def test_off_by_default_and_out_of_the_hash_until_set():
    assert MPCConfig().qp_fallback == "off"
    assert config_hash(MPCConfig(qp_fallback="off")) == config_hash(MPCConfig())
    assert config_hash(MPCConfig(qp_fallback="daqp")) != config_hash(MPCConfig())
    with pytest.raises(ConfigError, match="qp_fallback"):
        MPCConfig(qp_fallback="osqp")
    assert stack_preset("sofar-5") == dataclasses.replace(
        stack_preset("sofar-4"), mpc=dataclasses.replace(stack_preset("sofar-4").mpc, qp_fallback="daqp"))
    for preset in ("sofar-1", "sofar-4", "paper", "sofar-daqp"):
        assert stack_preset(preset).mpc.qp_fallback == "off"
    assert stack_preset("sofar-13").mpc.qp_fallback == "daqp"  # the default from "sofar-6" to "sofar-13"
    assert stack_preset("sofar").mpc.qp_solver == "daqp"  # "sofar-17": DAQP solves every QP, none to fall back from


def _piqp_always_fails(monkeypatch):
    """Make the PIQP backend report a failure on every QP (as on the QPs it cannot solve)."""
    def fail(qs, data, cfg):
        return None, 100, "piqp status Status.PIQP_MAX_ITER_REACHED"

    monkeypatch.setattr(backends, "_solve_piqp", fail)


def test_with_every_piqp_solve_failing_the_fallback_solves_the_same_qps(monkeypatch):
    """The fallback returns DAQP's solution of the same QP: the MPC's plan equals that of the DAQP backend (the
    condensed QP of the same structure; both set up afresh), and it is counted. Without the fallback every solve
    fails."""
    stage, x0 = make_stage(v_ref=30.0), np.array([0.0, 1.0, 0.05, 25.0, 0.0])
    opponents = np.array([[30.0, 0.5, 20.0]])  # a car ahead: DCBF rows, and the extra iteration's margin test
    direct = MPCDCBF(MPCConfig(qp_solver="daqp")).solve(x0, stage, opponents, 0.3)
    _piqp_always_fails(monkeypatch)
    off = MPCDCBF(MPCConfig())
    assert not off.solve(x0, stage, opponents, 0.3).success and off.n_qp_fallbacks == 0
    on = MPCDCBF(MPCConfig(qp_fallback="daqp"))
    res = on.solve(x0, stage, opponents, 0.3)
    assert res.success and res.qp_fallbacks >= 1 and on.n_qp_fallbacks == res.qp_fallbacks
    assert res.n_opponents == direct.n_opponents == 1
    np.testing.assert_allclose(res.u, direct.u, atol=1e-9)
    np.testing.assert_allclose(res.x_pred, direct.x_pred, atol=1e-8)
    clone = copy.deepcopy(on)  # the fallback's DAQP model is not copied: the copy sets one up afresh
    assert clone.solve(x0, stage, opponents, 0.3).success


def test_a_start_deep_inside_the_margin_drives_off_with_the_fallback():
    """Dynamic world (track margin 2.2 m), Laguna Seca 144 m into the lap, the car at rest 0.15 m from the left
    edge: PIQP fails on every QP of that start (a feasible QP: docs/decisions/qp-backend.md) and the MPC brakes;
    with DAQP as the fallback the car drives off, no MPC solve failing."""
    from sofar_agents.evaluation.standing_start import Placement, drive_off

    base = make_env_config({"stack": "sofar-1", "scenario": "dynamic"}, track="LagunaSeca")
    place = Placement(143.53679664, 8.26407974694353, "left", 0.15)
    outcome = {}
    for fallback in ("off", "daqp"):
        stack = dataclasses.replace(base.stack, mpc=dataclasses.replace(base.stack.mpc, qp_fallback=fallback))
        env = gym.make("SOfAR-LagunaSeca-v0", config=dataclasses.replace(base, stack=stack))
        try:
            outcome[fallback] = drive_off(env, place, 0.5, duration=5.0, min_distance=5.0)
            outcome[fallback] += (env.unwrapped.stack.counters["qp_fallbacks"],)
        finally:
            env.close()
    distance, _, _, failures, ok, fallbacks = outcome["off"]
    assert not ok and distance < 0.5 and failures == 50 and fallbacks == 0
    distance, _, off_track, failures, ok, fallbacks = outcome["daqp"]
    assert ok and distance > 10.0 and not off_track and failures == 0 and fallbacks >= 1
