"""The DAQP backend (``qp_solver = "daqp"``): the condensed QP with soft rows is the sparse QP.

Agreement is checked on the QPs of short closed loops (the ring road of ``bench/bench_mpc.py``; the
reference-point track rows and, with ``track_rows = "ends"``, the explicit track slack) against a
tight reference (PIQP, fresh set-up, tolerances 1e-11). DAQP's active-set solution is exact up to
rounding and its primal tolerance 1e-9, so it must sit much closer to the reference than PIQP at its
default tolerances (measured: PIQP 5e-6 on du_0, 3e-5 on the plan): 1e-6 on du_0 and 1e-5 on the plan
and the slacks (measured 4e-8 and 3e-7).
"""

import numpy as np
import pytest

import daqp
from sofar_env.control.mpc import MPCConfig, MPCDCBF
from sofar_env.control.mpc import condensed
from sofar_env.control.mpc.backends import solve_qp
from sofar_env.errors import ConfigError

from .scenarios import make_stage


def test_config_accepts_daqp():
    assert MPCConfig(qp_solver="daqp").qp_solver == "daqp"
    with pytest.raises(ConfigError):
        MPCConfig(qp_solver="qpoases")


@pytest.mark.parametrize("a", [1.0, 2.0])
def test_daqp_soft_rows_have_per_row_weights_in_row_units(a):
    """DAQP adds ``w s + s^2 / (2 rho)`` for the violation ``s`` of a soft row in the row's units, per row
    and per side (the contract :mod:`.condensed` builds the weights on)."""
    model = daqp.Model()
    # min x^2/2 - 10 x + y^2/2 + 10 y  s.t.  a x <= 1 (soft: rho 0.1, w 3),  a y >= -1 (soft: rho 0.5, w 1)
    model.setup(np.eye(2), np.array([-10.0, 10.0]), np.diag([a, a]), np.array([1.0, np.inf]),
                np.array([-np.inf, -1.0]), np.array([8, 8], dtype=np.int32))
    rho, w = np.array([0.1, 0.5]), np.array([3.0, 1.0])
    model.soft_weights(rho_l=rho, rho_u=rho, w_l=w, w_u=w)
    x, _, flag, _ = model.solve()
    # x - 10 + a (w + (a x - 1) / rho) = 0, and the mirror image for y
    expect = (10.0 - a * w + a / rho) / (1.0 + a * a / rho)
    assert flag == 2
    np.testing.assert_allclose(x, [expect[0], -expect[1]], rtol=1e-12)


@pytest.mark.parametrize("track_rows", ["reference", "ends"])
def test_daqp_agrees_with_piqp_and_a_tight_reference(bench, cache_dir, track_rows):
    cfg = MPCConfig(cache_dir=cache_dir, track_rows=track_rows)
    qps = bench.record_qps(steps=40, cfg=cfg)
    sol = bench.solve_all(qps, cfg)
    assert not any(z is None for z in sol["daqp"] + sol["piqp"] + sol["ref"])
    if track_rows == "ends":  # the end rows' shared slack stays a decision variable
        qs = qps[-1][0]
        assert len(condensed.CondensedDAQP(qs).expl_cols) == cfg.horizon
    with_rows = sum(qs.m > 0 or qs.lat or qs.trk for qs, _ in qps)
    assert with_rows > 0  # some QPs with soft rows
    acc = bench.accuracy(qps, sol, "daqp")
    assert acc["first_input"] < 1e-6 and acc["plan"] < 1e-5
    acc_piqp = bench.accuracy(qps, sol, "piqp")
    both = bench.accuracy(qps, sol, "daqp", "piqp")
    assert both["first_input"] <= acc_piqp["first_input"] + 1e-6 and both["plan"] <= acc_piqp["plan"] + 1e-5
    slack = max(float(np.abs((zd - zr).reshape(-1, qs.nb)[:, 7:]).max(initial=0.0))
                for (qs, _), zd, zr in zip(qps, sol["daqp"], sol["ref"]))
    assert slack < 1e-5


def test_condensed_qp_is_the_sparse_qp_on_the_inputs(bench, cache_dir):
    """The compiled condensing against the sparse QP: for inputs v (and explicit slacks), the states from
    the condensing satisfy the equality rows, the condensed cost differs from the sparse cost (soft slacks
    at 0) by a constant, each condensed row is its row of G, and the soft weights are c / g and g^2 / p."""
    rng = np.random.default_rng(0)
    qps = bench.record_qps(steps=30, cfg=MPCConfig(cache_dir=cache_dir, track_rows="ends"))
    qps = sorted(qps, key=lambda qd: (qd[0].m, qd[0].lat))[-3:]  # the ones with the most rows
    assert qps[-1][0].m > 0
    for qs, data in qps:
        cd = condensed.CondensedDAQP(qs)
        c, b = data[0], data[1]
        hess, f, amat, bu, bl, rho, w, sol, go, gabs = cd.condense(qs, data)
        nu, nx, nh, nv = len(cd.u_cols), len(cd.x_cols), len(cd.hard_rows), cd.nv
        assert len(cd.expl_cols) == cfg_horizon(qs) and len(cd.soft_cols) > 0

        def z_of(v):
            z = np.zeros(qs.nz)
            z[cd.u_cols], z[cd.expl_cols] = v[:nu], v[nu:]
            z[cd.x_cols] = sol[:, :nu] @ v[:nu] + sol[:, nu]
            return z

        def sparse_cost(z):
            return 0.5 * z @ (qs.P @ z) + c @ z

        vs = [rng.normal(size=nv) for _ in range(3)]
        zs = [z_of(v) for v in vs]
        for v, z in zip(vs, zs):
            np.testing.assert_allclose(qs.A @ z, b, atol=1e-9)
            gz = qs.G @ z
            np.testing.assert_allclose(amat[nx:nx + nh] @ v + go[cd.hard_rows], gz[cd.hard_rows], atol=1e-9)
            np.testing.assert_allclose(amat[nx + nh:] @ v + go[cd.soft_up], gz[cd.soft_up], atol=1e-9)
            np.testing.assert_allclose(amat[:nx] @ v, z[cd.x_cols] - sol[:, nu], atol=1e-9)
        dq = [0.5 * v @ hess @ v + f @ v for v in vs]
        dj = [sparse_cost(z) for z in zs]
        np.testing.assert_allclose(np.diff(dq), np.diff(dj), rtol=1e-9, atol=1e-9)
        g = qs.G.toarray()[cd.soft_up, cd.soft_cols]
        np.testing.assert_allclose(gabs, np.abs(g))
        np.testing.assert_allclose(w[nv + nx + nh:], c[cd.soft_cols] / np.abs(g))
        np.testing.assert_allclose(rho[nv + nx + nh:], g * g / qs.P.diagonal()[cd.soft_cols])


def cfg_horizon(qs) -> int:
    return qs.nz // qs.nb


@pytest.mark.parametrize("tight", [False, True])
def test_daqp_solves_an_opponent_qp_like_piqp(cache_dir, tight):
    """From identical states: the whole solve (several SQP iterations with an active barrier); ``tight``:
    on a narrow curved road the track and lateral-acceleration rows are in the QP too, with slack."""
    x0, opp = np.array([0.0, 0.3, 0.0, 40.0, 0.0]), np.array([[20.0, 0.5, 35.0]])
    stage = make_stage(n_ref=1.5, kappa=0.02, half_width=2.0) if tight else make_stage()
    res = {}
    for name in ("piqp", "daqp"):
        mpc = MPCDCBF(MPCConfig(cache_dir=cache_dir, qp_solver=name))
        res[name] = mpc.solve(x0, stage, opp, 0.5)
        assert res[name].success and res[name].n_opponents == 1
        if tight:
            assert any(qs.lat and qs.trk for qs in mpc._qp.values())
            assert res[name].slack["track"] > 0.0 and res[name].slack["lat_acc"] > 0.0
    if tight:
        for key in ("track", "lat_acc", "barrier"):
            assert res["daqp"].slack[key] == pytest.approx(res["piqp"].slack[key], rel=1e-3, abs=1e-6)
    np.testing.assert_allclose(res["daqp"].u, res["piqp"].u, atol=1e-4)
    np.testing.assert_allclose(res["daqp"].x_pred, res["piqp"].x_pred, atol=1e-3)


def test_daqp_trouble_is_returned_not_raised(bench, cache_dir):
    qs, data = bench.record_qps(steps=2, cfg=MPCConfig(cache_dir=cache_dir))[-1]
    qs = bench._fresh(qs, "daqp")
    c, b, hl, hu, xl, xu = (d.copy() for d in data)
    xl[0], xu[0] = 1.0, -1.0  # an empty box on du_0: infeasible
    z, _, message = solve_qp(qs, (c, b, hl, hu, xl, xu), MPCConfig())
    assert z is None and "daqp" in message and qs.solver is None
    z, _, message = solve_qp(qs, data, MPCConfig())  # a fresh set-up solves the intact QP
    assert z is not None and message == "solved"


def test_daqp_failure_falls_back(cache_dir, monkeypatch):
    mpc = MPCDCBF(MPCConfig(cache_dir=cache_dir, qp_solver="daqp"))
    x0, stage = np.array([0.0, 0.3, 0.0, 40.0, 0.0]), make_stage()
    assert mpc.solve(x0, stage, np.zeros((0, 3)), 0.5).success
    monkeypatch.setattr(condensed.CondensedDAQP, "solve", lambda self, qs, data: (None, 3, "daqp exit flag -4"))
    res = mpc.solve(x0, stage, np.zeros((0, 3)), 0.5)
    assert not res.success and res.status == "fallback_shift" and mpc.n_failures == 1

    def boom(self, qs, data):
        raise ValueError("soft row pair outside the contract")

    monkeypatch.setattr(condensed.CondensedDAQP, "solve", boom)
    res = mpc.solve(x0, stage, np.zeros((0, 3)), 0.5)
    assert not res.success and mpc.n_failures == 2


def test_env_with_daqp_runs_on_laguna_seca(monkeypatch):
    import gymnasium as gym

    import sofar_env  # noqa: F401  (registers the ids)

    solves = []
    inner = condensed.CondensedDAQP.solve

    def counted(self, qs, data):
        out = inner(self, qs, data)
        solves.append(out[0] is not None)
        return out

    monkeypatch.setattr(condensed.CondensedDAQP, "solve", counted)

    env = gym.make("SOfAR-LagunaSeca-v0", stack={"mpc": {"qp_solver": "daqp"}})
    try:
        env.reset(seed=0)
        env.action_space.seed(0)
        assert env.unwrapped.config.stack.mpc.qp_solver == "daqp"
        steps = 0
        for steps in range(1, 301):
            _, _, term, trunc, info = env.step(env.action_space.sample())
            assert info["mpc_failures"] == 0, info["mpc_status"]
            if term or trunc:
                env.reset(seed=steps)
    finally:
        env.close()
    assert steps == 300 and len(solves) >= 300 and all(solves)
