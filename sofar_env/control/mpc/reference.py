"""IPOPT reference: the MPC-DCBF's nonlinear program solved to convergence, for validation.

The NLP is assembled from the very stage function whose Jacobians the real-time
iteration uses (:func:`~.model.stage_function`, called once per stage inside the NLP),
and from the same cost weights, slack weights, hard box, track limits and opponent
prediction (:mod:`.model`); only the solver differs. Variables, stage-major: block k
(k = 0..N-1) = [u_k (2), x_{k+1} (5), sigma_lat_{k+1}, sigma_trk_{k+1},
sigma_cbf_{k,0..m-1}], slacks unscaled. One NLP is built per number of opponents ``m``
(the data enter as parameters) and reused. IPOPT runs to a tolerance of 1e-10.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ...vehicle import VehicleParams
from .ends import EndOffsets
from .layout import N_FIXED
from .model import (DUMMY_OPPONENT, OPPONENT_ROWS, predict_opponents, slack_weights, stage_reference, track_limits,
                    tracking_weights, variable_box)
from .types import MPCConfig

__all__ = ["IpoptReference", "ReferenceSolution"]

_IPOPT_OPTIONS = {"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes", "ipopt.tol": 1e-10,
                  "ipopt.constr_viol_tol": 1e-10, "ipopt.max_iter": 1000}


@dataclass(frozen=True)
class ReferenceSolution:
    """Outcome of one IPOPT solve."""

    success: bool
    """True when IPOPT converged to finite values."""
    message: str
    """IPOPT's return status."""
    iterations: int
    """IPOPT iterations."""
    x: np.ndarray | None = None
    """(N+1, 5) states, x_0 the given state (None on failure)."""
    u: np.ndarray | None = None
    """(N, 2) inputs."""
    slack_lat_acc: np.ndarray | None = None
    """(N,) lateral-acceleration slacks of x_1..x_N [m/s^2]."""
    slack_track: np.ndarray | None = None
    """(N,) track slacks of x_1..x_N [m]."""
    slack_barrier: np.ndarray | None = None
    """(N, m) DCBF slacks of the transitions x_k -> x_{k+1} [-]."""
    objective: float | None = None
    """The NLP's cost at the solution (tracking and slack terms; None on failure): two solutions of one problem,
    e.g. from two guesses, compare by it."""


class IpoptReference:
    """The MPC-DCBF NLP over ``stage`` (the stage function of the RTI), solved with IPOPT."""

    def __init__(self, cfg: MPCConfig, vehicle: VehicleParams, stage):
        self.config = cfg
        self.vehicle = vehicle
        self.stage = stage
        self.slots = int(stage.size2_in(4))
        self._t = cfg.time_grid()
        self._dt = np.concatenate([np.diff(self._t), [cfg.ts]])
        self._nlp: dict[int, Any] = {}

    def _build(self, m: int):
        import casadi as ca

        cfg = self.config
        p = self.vehicle
        n_h = cfg.horizon
        ms = self.slots
        nbuf = _n_buffer(cfg)
        nb = N_FIXED + 2 + nbuf + m
        w = ca.SX.sym("w", n_h * nb)
        x0 = ca.SX.sym("x0", 5)
        kappa = ca.SX.sym("kappa", n_h + 1)
        ref = ca.SX.sym("ref", n_h * N_FIXED)
        n_lo = ca.SX.sym("n_lo", n_h)
        n_hi = ca.SX.sym("n_hi", n_h)
        opp = ca.SX.sym("opp", OPPONENT_ROWS * ms * (n_h + 1))
        gamma = ca.SX.sym("gamma")
        par = ca.vertcat(x0, kappa, ref, n_lo, n_hi, opp, gamma)
        weights = tracking_weights(cfg)
        z1, z2 = slack_weights(cfg, True, True, m, bool(nbuf))
        ends = EndOffsets.for_rows(cfg.track_rows, p)

        blocks = [w[k * nb:(k + 1) * nb] for k in range(n_h)]
        xs = [x0] + [b[2:7] for b in blocks]
        us = [b[0:2] for b in blocks] + [ca.SX.zeros(2)]
        # the stage function at every stage k = 0..N: f_k, alat_k, h_k (as in the RTI's linearisation)
        out = [self.stage(xs[k], us[k], kappa[k], float(self._dt[k]),
                          ca.reshape(opp[OPPONENT_ROWS * ms * k:OPPONENT_ROWS * ms * (k + 1)], OPPONENT_ROWS, ms))
               for k in range(n_h + 1)]
        cost = 0
        g, lbg, ubg = [], [], []
        for k in range(n_h):
            b = blocks[k]
            f_k, _, h_k = out[k]
            _, alat, h_next = out[k + 1]
            x = xs[k + 1]
            sl, st = b[7], b[8] + (b[9] if nbuf else 0.0)  # track: its slack plus the buffer slack
            g.append(x - f_k)
            lbg += [0.0] * 5
            ubg += [0.0] * 5
            g += [alat - sl, alat + sl]
            lbg += [-ca.inf, -p.lat_acc_max]
            ubg += [p.lat_acc_max, ca.inf]
            # the track rows bound the reference point, or both ends of the car (rows as in the RTI's QP)
            if ends is None:
                g += [x[1] - st - n_hi[k], x[1] + st - n_lo[k]]
                lbg += [-ca.inf, 0.0]
                ubg += [0.0, ca.inf]
            else:
                up, lo, rear_up, rear_lo = ends.symbolic(x[2], kappa[k + 1])
                g += [x[1] + up - st - n_hi[k], x[1] + lo + st - n_lo[k],
                      x[1] + rear_up - st - n_hi[k], x[1] + rear_lo + st - n_lo[k]]
                lbg += [-ca.inf, 0.0, -ca.inf, 0.0]
                ubg += [0.0, ca.inf, 0.0, ca.inf]
            for i in range(m):
                g.append((1.0 - gamma) * h_k[i] - h_next[i] - b[9 + nbuf + i])
                lbg.append(-ca.inf)
                ubg.append(0.0)
            cost += sum(weights[j] * (b[j] - ref[k * N_FIXED + j]) ** 2 for j in range(N_FIXED) if weights[j] != 0.0)
            cost += sum(z1[j] * b[7 + j] + 0.5 * z2[j] * b[7 + j] ** 2 for j in range(2 + nbuf + m))
        nlp = {"x": w, "p": par, "f": cost, "g": ca.vertcat(*g)}
        solver = ca.nlpsol(f"sofar_mpc_ipopt_{m}", "ipopt", nlp, _IPOPT_OPTIONS)
        return solver, np.array(lbg, dtype=float), np.array(ubg, dtype=float)

    def solve(self, x0: np.ndarray, arrays: np.ndarray, sel: np.ndarray, gamma: float, xbar: np.ndarray,
              ubar: np.ndarray) -> ReferenceSolution:
        """Solve from the guess ``(xbar, ubar)``; ``arrays`` the (5, N+1) stage rows, ``sel`` the
        (m, 3) opponents with DCBF constraints (m <= slots). Never raises for solver trouble."""
        n_h = self.config.horizon
        m = len(sel)
        if m not in self._nlp:
            self._nlp[m] = self._build(m)
        solver, lbg, ubg = self._nlp[m]
        nbuf = _n_buffer(self.config)
        nb = N_FIXED + 2 + nbuf + m
        o = np.empty((n_h + 1, self.slots, OPPONENT_ROWS))
        o[:] = DUMMY_OPPONENT
        o[:, :m] = predict_opponents(sel, self._t)
        n_lo, n_hi = track_limits(self.config, arrays)
        par = np.concatenate([x0, arrays[0], stage_reference(arrays).ravel(), n_lo, n_hi, o.ravel(), [gamma]])
        lo7, hi7 = variable_box(self.vehicle)
        lbx = np.full((n_h, nb), -np.inf)
        ubx = np.full((n_h, nb), np.inf)
        lbx[:, :N_FIXED], ubx[:, :N_FIXED] = lo7, hi7
        lbx[:, N_FIXED:] = 0.0
        if nbuf:
            ubx[:, N_FIXED + 2] = self.config.track_buffer
        w0 = np.zeros((n_h, nb))
        w0[:, 0:2] = ubar
        w0[:, 2:7] = xbar[1:]
        w0 = np.clip(w0, lbx, ubx)
        try:
            sol = solver(x0=w0.ravel(), p=par, lbx=lbx.ravel(), ubx=ubx.ravel(), lbg=lbg, ubg=ubg)
            stats = solver.stats()
            ok = bool(stats.get("success", False))
            iters = int(stats.get("iter_count", 0))
            z = np.array(sol["x"]).reshape(-1)
            objective = float(sol["f"])
        except RuntimeError as exc:
            return ReferenceSolution(False, str(exc), 0)
        message = str(stats.get("return_status"))
        if not ok or not np.isfinite(z).all():
            return ReferenceSolution(False, message, iters)
        zz = z.reshape(n_h, nb)
        return ReferenceSolution(True, message, iters, x=np.vstack([x0, zz[:, 2:7]]), u=zz[:, 0:2].copy(),
                                 slack_lat_acc=zz[:, 7].copy(), slack_track=zz[:, 8] + (zz[:, 9] if nbuf else 0.0),
                                 slack_barrier=zz[:, 9 + nbuf:].copy(), objective=objective)


def _n_buffer(cfg: MPCConfig) -> int:
    """1 where the track rows have the buffer slack (``MPCConfig.track_buffer``; the config allows it with end rows
    only), else 0."""
    return int(cfg.track_buffer > 0.0)
