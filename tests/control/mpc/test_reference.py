"""IPOPT reference: the same NLP as the RTI (same stage function), converged; RTI agrees with it."""

import logging

import numpy as np
import pytest

from sofar_env.control.mpc import MPCConfig, MPCDCBF
from sofar_env.vehicle import AV21

from .scenarios import make_stage


@pytest.mark.parametrize("kappa", [0.0, 1.0 / 150.0])
def test_rti_first_control_matches_ipopt(cache_dir, kappa):
    """At a fixed state, repeated RTI steps (no shift) converge to the NLP optimum."""
    cfg = MPCConfig(control_dt=0.0, cache_dir=cache_dir)
    rng = np.random.default_rng(1)
    for _ in range(4):
        x0 = np.array([0.0, rng.uniform(-1.5, 1.5), rng.uniform(-0.01, 0.01), rng.uniform(30.0, 45.0),
                       kappa * AV21.wheelbase + rng.uniform(-0.005, 0.005)])
        # references close to the state, so that the optimal inputs are mostly not saturated
        stage = make_stage(v_ref=x0[3] + rng.uniform(-1.0, 1.0), n_ref=x0[1] + rng.uniform(-0.2, 0.2), kappa=kappa)
        # one opponent ahead and one behind in the neighbouring lane: barrier rows present
        side = -np.sign(x0[1] + 1e-9)
        opp = np.array([[rng.uniform(25.0, 45.0), 4.0 * side, 32.0], [-25.0, 4.5 * side, 38.0]])
        gamma = rng.uniform(0.1, 0.9)
        rti = MPCDCBF(cfg)
        for _ in range(8):
            res = rti.solve(x0, stage, opp, gamma)
            assert res.success
        ref = MPCDCBF(cfg).solve_converged(x0, stage, opp, gamma)
        assert ref.success and ref.status == "solved"
        logging.getLogger(__name__).info("RTI %s IPOPT %s", res.u, ref.u)
        assert abs(res.u[0] - ref.u[0]) < 0.05, (res.u, ref.u)
        assert abs(res.u[1] - ref.u[1]) < 0.005, (res.u, ref.u)
        np.testing.assert_allclose(res.x_pred[:, 1], ref.x_pred[:, 1], atol=0.02)


def test_reference_solution_satisfies_the_stage_function(cache_dir):
    """The NLP is built from the RTI's own stage function: its solution meets the dynamics, the
    DCBF and the bounds evaluated with that function, to IPOPT's tolerance."""
    cfg = MPCConfig(cache_dir=cache_dir)
    mpc = MPCDCBF(cfg)
    x0 = np.array([0.0, 0.2, 0.0, 42.0, 0.0])
    stage = make_stage(v_ref=45.0, n_ref=-0.5, kappa=1 / 250)
    opp = np.array([[22.0, 0.0, 34.0], [-12.0, 3.0, 44.0]])
    gamma = 0.3
    res = mpc.solve_converged(x0, stage, opp, gamma)
    assert res.success and res.n_opponents == 2
    assert mpc._reference.stage is mpc._lin.stage  # one stage definition for both solvers
    t = cfg.time_grid()
    dt = np.concatenate([np.diff(t), [cfg.ts]])
    o = np.zeros((len(t), mpc._lin.slots, 4))
    o[:] = (50.0, 0.0, 0.0, 0.0)
    o[:, :2, 0] = opp[:, 0] + opp[:, 2] * t[:, None]
    o[:, :2, 1:3] = opp[:, 1:]
    u = np.vstack([res.u_pred, [0.0, 0.0]])
    outs = [[np.asarray(v).ravel() for v in mpc._lin.stage(res.x_pred[k], u[k], stage.kappa[k], dt[k], o[k].T)]
            for k in range(len(t))]
    f = np.array([r[0] for r in outs])
    alat = np.array([r[1][0] for r in outs])
    h = np.array([r[2][:2] for r in outs])
    np.testing.assert_allclose(res.x_pred[1:], f[:-1], atol=1e-8)
    dcbf = (1.0 - gamma) * h[:-1] - h[1:]
    assert dcbf.max() <= res.slack["barrier"] + 1e-8
    assert np.abs(alat[1:]).max() <= AV21.lat_acc_max + res.slack["lat_acc"] + 1e-8
    assert np.all(np.abs(res.x_pred[1:, 1]) <= 6.0 - cfg.track_margin + res.slack["track"] + 1e-8)
    assert np.all(np.abs(res.u_pred[:, 1]) <= AV21.steer_rate_max + 1e-8)
    assert np.all(res.x_pred[:, 3] >= -1e-8)
    # the converged plan becomes the warm start
    np.testing.assert_allclose(mpc.predicted_s()[:-2], (np.interp(t + 0.1, t, res.x_pred[:, 0])
                                                       - np.interp(0.1, t, res.x_pred[:, 0]))[:-2], atol=1e-9)
