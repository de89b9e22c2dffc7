"""The bug-compatible MPC: :class:`ReferenceNumericsMPC` (see the package docstring for what it reproduces).

One SQP real-time iteration per call, as acados' ``SQP_RTI`` runs it for the reference:

1. the linearisation point is the previous iterate shifted by one interval (``x_k <- x_{k+1}``, the last
   state and input kept), **not** re-anchored to the ego's new position; on the first call the reference
   rows ``(s, n_ref, 0, v_ref, atan(L kappa))`` with zero inputs;
2. the stage function and its Jacobians at every interval (:func:`.ocp.linearisation`);
3. full condensing onto the input steps (the state at node 0 fixed to the measured one), the stage costs
   and slack penalties multiplied by the interval length; the soft rows at nodes 1..N-1 (0..N-1 for the
   DCBF with ``first_transition_dcbf``), the steering bound at nodes 1..N-1 as hard rows;
4. HPIPM's dense interior-point solve (:mod:`.hpipm`) from a cold start with acados' options;
5. a status of ``success`` or ``max_iter`` is a solved QP (acados' SQP_RTI accepts the iteration cap and
   applies the step); ``min_step`` or ``nan`` is a failure: the iterate stays as it was and the command is
   throttle 0, steering towards 0 (``zero_command_on_failure``).

The command: ``a = u_0``, and the steering angle of node 1, ``delta_1 = delta_0 + 0.075 delta_dot_0``
(clipped to the steering bound), reached over the plant period: ``delta_dot = (delta_1 - delta_0) /
control_dt``.
"""

from __future__ import annotations

import logging
import math
import time

import numpy as np

from ...vehicle import AV21, VehicleParams
from ..mpc.types import STATUS_SOLVED, MPCConfig, MPCResult, MPCStageData, validate_arguments
from .config import PHANTOM_S, PHANTOM_SLOT_STEP, ReferenceNumerics
from .hpipm import DenseQP
from .ocp import ROWS_FIXED, linearisation

__all__ = ["ReferenceNumericsMPC", "STATUS_ZERO_COMMAND", "slot_rows", "condense"]

logger = logging.getLogger(__name__)

STATUS_ZERO_COMMAND = "fallback_zero"
"""Status of a failed solve whose command is throttle 0 and steering towards 0."""


def slot_rows(opponents: np.ndarray, v: float, rn: ReferenceNumerics, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """``(rows, real)``: the ``rn.slots`` rows ``(s_rel, n, v)`` the reference gives its OCP, and which of
    them are opponents on the target line.

    ``opponents`` are rows ``(gap, n, v)`` of every opponent. One whose gap lies in ``[0, window]``
    (``window = window_points * spacing * max(0.1 v, 1.5)`` m, the length of the target line) keeps its
    row; the others become phantoms ``(PHANTOM_S, 0, v_o)``; slots left over ``(PHANTOM_S + 100 i, 0, 0)``.
    Opponents on the line come first, nearest first.
    """
    window = rn.window_points * spacing * max(0.1 * float(v), 1.5)
    opp = np.asarray(opponents, float).reshape(-1, opponents.shape[-1] if np.ndim(opponents) == 2 else 3)[:, :3]
    on_line = (opp[:, 0] >= 0.0) & (opp[:, 0] <= window)
    order = np.concatenate([np.flatnonzero(on_line)[np.argsort(opp[on_line, 0], kind="stable")],
                            np.flatnonzero(~on_line)])
    rows = np.zeros((rn.slots, 3))
    real = np.zeros(rn.slots, dtype=bool)
    for i in range(rn.slots):
        if i < len(order):
            j = order[i]
            rows[i] = opp[j] if on_line[j] else (PHANTOM_S, 0.0, opp[j, 2])
            real[i] = bool(on_line[j])
        else:
            rows[i] = (PHANTOM_S + PHANTOM_SLOT_STEP * i, 0.0, 0.0)
    return rows, real


def condense(A: np.ndarray, B: np.ndarray, f: np.ndarray, x_next: np.ndarray,
             dx0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Full condensing of the linearised dynamics ``dx_{k+1} = A_k dx_k + B_k du_k + f_k - x_next_k`` (k < N;
    ``f_k`` the model's successor of the linearisation point, ``x_next_k`` the point's next state) from a fixed
    ``dx_0``: ``(G, xoff)`` with ``dx_k = xoff_k + G_k du`` for the stacked input steps ``du``
    (``G``: (N+1, nx, N nu))."""
    n, nx, nu = B.shape
    G = np.zeros((n + 1, nx, n * nu))
    xoff = np.zeros((n + 1, nx))
    xoff[0] = dx0
    for k in range(n):
        xoff[k + 1] = A[k] @ xoff[k] + f[k] - x_next[k]
        G[k + 1] = A[k] @ G[k]
        G[k + 1][:, nu * k:nu * (k + 1)] += B[k]
    return G, xoff


class ReferenceNumericsMPC:
    """Bug-compatible MPC-DCBF: the reference implementation's formulation and numerics, defects included.

    Same interface as :class:`~sofar_env.control.mpc.MPCDCBF` (``solve``, ``predicted_s``, ``reset``,
    ``n_failures``). ``config`` gives the time grid (uniform: ``first_step`` must equal ``ts``), the plant
    period, the cost and slack weights; ``numerics`` the reproduced defects; ``spacing`` the target-line
    spacing factor of the circuit (:meth:`ReferenceNumerics.spacing`). Never a default of any preset
    but ``"reference-numerics"``. Not picklable (HPIPM's workspace): rebuild it from its arguments.
    """

    def __init__(self, config: MPCConfig, numerics: ReferenceNumerics = ReferenceNumerics(),
                 vehicle: VehicleParams = AV21, spacing: float = 1.0):
        if abs(config.dt0 - config.ts) > 1e-12:
            raise ValueError(f"the reference's grid is uniform: need mpc.first_step == mpc.ts, got "
                             f"{config.dt0} and {config.ts}")
        self.config, self.numerics, self.vehicle, self.spacing = config, numerics, vehicle, float(spacing)
        n = self._n = config.horizon
        self._t = config.time_grid()
        self._lin, self.codegen_info = linearisation(numerics, vehicle, config.ts, n, config.cache_dir,
                                                     config.compile)
        self._qp: dict[int, DenseQP] = {}
        w = np.full(n + 1, config.ts if numerics.cost_scaled else 1.0)
        w[n] = 1.0
        self._w = w  # cost weight of node k (stage cost times the interval, terminal cost 1)
        self._q = np.asarray(config.q, float)
        self._r = np.asarray(config.r, float)
        self._u_lo = np.array([vehicle.a_min, -vehicle.steer_rate_max])
        self._u_hi = np.array([vehicle.a_max, vehicle.steer_rate_max])
        self.n_failures = 0
        self.n_restarts = 0
        self.n_restarts_taken = 0
        self.qp_status_counts = {k: 0 for k in range(5)}
        """HPIPM statuses since construction or reset (0 success, 1 iteration cap, 2 min step, 3 NaN)."""
        self.reset()

    def reset(self) -> None:
        """Forget the iterate and zero the counters."""
        self._xg: np.ndarray | None = None
        self._ug: np.ndarray | None = None
        self.n_failures = 0
        self.qp_status_counts = {k: 0 for k in range(5)}

    def predicted_s(self, v0: float | None = None) -> np.ndarray:
        """(N+1,) arc lengths at which the caller evaluates the track: the shifted iterate's, relative to
        its first node, or constant speed ``v0`` without an iterate."""
        if self._xg is not None:
            return self._xg[:, 0] - self._xg[0, 0]
        return max(float(v0 or 0.0), 0.0) * self._t

    # ------------------------------------------------------------------ the QP

    def _rows(self, real: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(node, row)`` of every soft row in the QP, in order."""
        rn = self.numerics
        slots = np.flatnonzero(real) if not rn.phantoms else np.arange(rn.slots)
        per_node = np.concatenate([np.arange(ROWS_FIXED), ROWS_FIXED + slots])
        nodes, rows = [], []
        if rn.first_transition_dcbf:
            nodes.append(np.zeros(len(slots), dtype=int))
            rows.append(ROWS_FIXED + slots)
        for k in range(1, self._n):
            nodes.append(np.full(len(per_node), k))
            rows.append(per_node)
        return np.concatenate(nodes), np.concatenate(rows)

    def _dense_qp(self, n_soft: int) -> DenseQP:
        qp = self._qp.get(n_soft)
        if qp is None:
            nv, n_delta = 2 * self._n, self._n - 1
            idxs = nv + n_delta + np.arange(n_soft)
            qp = DenseQP(nv, np.arange(nv), n_delta + n_soft, idxs, self.numerics.qp)
            self._qp[n_soft] = qp
        return qp

    def _guess(self, x0: np.ndarray, arrays: np.ndarray, s_pred: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if self._xg is not None:
            return self._xg.copy(), self._ug.copy()
        x = np.zeros((self._n + 1, 5))
        x[:, 0] = s_pred
        x[:, 1] = arrays[1]
        x[:, 3] = arrays[2]
        x[:, 4] = np.arctan(self.vehicle.wheelbase * arrays[0])
        return x, np.zeros((self._n, 2))

    def solve(self, x0, stage: MPCStageData, opponents, gamma: float) -> MPCResult:
        """One real-time iteration (module docstring). ``opponents``: rows ``(gap, n, v)`` of every opponent
        (not only those near: the slots are filled as the reference fills them, :func:`slot_rows`)."""
        t_start = time.perf_counter()
        x0, arrays, opp, gamma = validate_arguments(x0, stage, opponents, gamma, self._n)
        slots, real = slot_rows(opp, x0[3], self.numerics, self.spacing)
        return self._solve(x0, arrays, slots, real, gamma, t_start)

    def solve_slots(self, x0, stage: MPCStageData, slots, gamma: float) -> MPCResult:
        """:meth:`solve` with the OCP's slot rows given as they are: ``slots`` is ``(numerics.slots, 3)`` rows
        ``(s_rel, n, v)``, each one counted as an opponent (no phantom is made and none is left out). For
        experiments that place the rows themselves, as the reference's own probes do."""
        t_start = time.perf_counter()
        rows = np.asarray(slots, float)
        if rows.shape != (self.numerics.slots, 3) or not np.all(np.isfinite(rows)):
            raise ValueError(f"slots must be {self.numerics.slots} finite rows (s_rel, n, v), got shape {rows.shape}")
        x0, arrays, _, gamma = validate_arguments(x0, stage, rows, gamma, self._n)
        return self._solve(x0, arrays, rows, np.ones(len(rows), dtype=bool), gamma, t_start)

    def _parameters(self, slots: np.ndarray, arrays: np.ndarray, gamma: float) -> np.ndarray:
        """The OCP's stage parameters ``(kappa, n_max, n_min, (s_o, n_o, v_o) per slot, gamma)`` of the N
        intervals, the slots predicted at constant speed along the track."""
        rn, n = self.numerics, self._n
        params = np.empty((4 + 3 * rn.slots, n))
        params[0], params[1], params[2] = arrays[0, :n], arrays[4, :n], arrays[3, :n]
        params[3:3 + 3 * rn.slots:3] = slots[:, 0:1] + slots[:, 2:3] * (np.arange(n) * self.config.ts)
        params[4:4 + 3 * rn.slots:3] = slots[:, 1:2]
        params[5:5 + 3 * rn.slots:3] = slots[:, 2:3]
        params[3 + 3 * rn.slots] = gamma
        return params

    def _objective(self, G, xoff, xbar, ubar, arrays) -> tuple[np.ndarray, np.ndarray]:
        """``(H, g)`` of the condensed QP: the weighted tracking of (n_ref, v_ref) (and of the other states
        with their weights) at nodes 1..N, and the input weights, in the input steps."""
        n, nv = self._n, 2 * self._n
        xref = np.zeros((n + 1, 5))
        xref[:, 1], xref[:, 3] = arrays[1], arrays[2]
        xref[:, 4] = np.arctan(self.vehicle.wheelbase * arrays[0])
        wq = self._w[1:, None] * self._q[None, :]  # (N, 5) weights of nodes 1..N
        Gs = G[1:]
        wr = np.tile(self._r, n) * np.repeat(self._w[:n], 2)
        H = 2.0 * np.einsum("kiv,ki,kiw->vw", Gs, wq, Gs)
        H[np.arange(nv), np.arange(nv)] += 2.0 * np.tile(self._r, n) * np.repeat(self._w[:n], 2)
        g = 2.0 * np.einsum("kiv,ki->v", Gs, wq * (xbar[1:] + xoff[1:] - xref[1:])) + 2.0 * (wr * ubar.reshape(-1))
        return H, g

    def _solve(self, x0, arrays, slots, real, gamma, t_start) -> MPCResult:
        """One real-time iteration on validated arguments and filled slots."""
        rn, n, cfg = self.numerics, self._n, self.config
        xbar, ubar = self._guess(x0, arrays, self.predicted_s(x0[3]))
        f, A, B, c, Cx, Cu = (np.asarray(a) for a in self._lin(xbar[:n].T, ubar.T, self._parameters(slots, arrays, gamma)))
        nr = c.shape[0]
        G, xoff = condense(A.reshape(5, n, 5).transpose(1, 0, 2), B.reshape(5, n, 2).transpose(1, 0, 2),
                           f.T, xbar[1:], x0 - xbar[0])
        Cx = Cx.reshape(nr, n, 5).transpose(1, 0, 2)
        Cu = Cu.reshape(nr, n, 2).transpose(1, 0, 2)
        H, g = self._objective(G, xoff, xbar, ubar, arrays)
        # rows: steering bound at nodes 1..N-1 (hard), then the soft rows
        nodes, rows = self._rows(real)
        dmax = self.vehicle.steer_max
        base = xbar[1:n, 4] + xoff[1:n, 4]
        C_soft = np.einsum("ri,riv->rv", Cx[nodes, rows], G[nodes]) if len(nodes) else np.zeros((0, 2 * n))
        C_soft[np.arange(len(nodes)), 2 * nodes] += Cu[nodes, rows, 0]
        C_soft[np.arange(len(nodes)), 2 * nodes + 1] += Cu[nodes, rows, 1]
        cbar = c[rows, nodes] + np.einsum("ri,ri->r", Cx[nodes, rows], xoff[nodes])
        lo = np.where(rows == 0, -rn.lat_acc_max, rn.lower_bound)
        hi = np.where(rows == 0, rn.lat_acc_max, 0.0)
        zl = np.array([cfg.lat_acc_slack, cfg.track_slack, cfg.track_slack] + [cfg.barrier_slack] * rn.slots)[rows]
        scale = self._w[nodes]
        qp = self._dense_qp(len(nodes))
        v, status, iters = qp.solve(H, g, np.tile(self._u_lo, n) - ubar.reshape(-1),
                                    np.tile(self._u_hi, n) - ubar.reshape(-1),
                                    np.vstack([G[1:n, 4, :], C_soft]),
                                    np.concatenate([-dmax - base, lo - cbar]),
                                    np.concatenate([dmax - base, hi - cbar]),
                                    zl[:, 1] * scale, zl[:, 0] * scale)
        self.qp_status_counts[status] = self.qp_status_counts.get(status, 0) + 1
        failed = status in (2, 3) or (status == 1 and rn.max_iter_is_failure) or not np.all(np.isfinite(v))
        if failed:
            return self._failure(x0, xbar, ubar, status, iters, t_start, slots, real)
        du = v.reshape(n, 2)
        xbar = xbar + xoff + G @ v
        ubar = ubar + du
        row_val = cbar + C_soft @ v
        is_real_cbf = (rows >= ROWS_FIXED) & real[np.maximum(rows - ROWS_FIXED, 0)]
        slack_cbf = float(max(row_val[is_real_cbf].max(), 0.0)) if is_real_cbf.any() else 0.0
        on_first = is_real_cbf & (nodes == 0)  # rows of the first transition (first_transition_dcbf only)
        first = float(max(row_val[on_first].max(), 0.0)) if on_first.any() else 0.0
        slack = {"lat_acc": float(max(np.abs(row_val[rows == 0]).max(initial=0.0) - rn.lat_acc_max, 0.0)),
                 "track": float(max(row_val[(rows == 1) | (rows == 2)].max(initial=0.0), 0.0)),
                 "barrier": slack_cbf}
        x_pred = xbar.copy()
        x_pred[:, 0] -= x_pred[0, 0]
        u = self._command(x0, ubar[0, 0], xbar[1, 4])
        self._shift(xbar, ubar)
        return MPCResult(u=u, x_pred=x_pred, u_pred=ubar.copy(), status=STATUS_SOLVED, success=True, slack=slack,
                         h_now=self._barrier_min(x0, slots, real), solve_time=time.perf_counter() - t_start,
                         qp_iterations=iters, sqp_iterations=1, barrier_slack_first=first,
                         n_opponents=int(real.sum()))

    # ------------------------------------------------------------------ helpers

    def _command(self, x0: np.ndarray, a: float, delta_1: float) -> np.ndarray:
        """``(a, delta_dot)`` for the plant: ``delta_1`` clipped to the bound, reached over the plant period."""
        p, period = self.vehicle, self.config.control_dt or self.config.ts
        delta_1 = min(max(delta_1, -p.steer_max), p.steer_max)
        return np.array([min(max(a, p.a_min), p.a_max),
                         min(max((delta_1 - x0[4]) / period, -p.steer_rate_max), p.steer_rate_max)])

    def _shift(self, xbar: np.ndarray, ubar: np.ndarray) -> None:
        """The next linearisation point: one interval on, last state and input kept, not re-anchored."""
        self._xg = np.vstack([xbar[1:], xbar[-1:]])
        self._ug = np.vstack([ubar[1:], ubar[-1:]])

    def _barrier_min(self, x0: np.ndarray, slots: np.ndarray, real: np.ndarray) -> float:
        """Smallest reference barrier at ``x0`` over the opponents on the target line (inf if none)."""
        if not real.any():
            return math.inf
        rn = self.numerics
        o = slots[real]
        a = rn.a0 + np.maximum(0.0, x0[3] - o[:, 2]) ** 2 / (2.0 * rn.a_brake)
        h = ((x0[0] - o[:, 0]) / a) ** 2 + ((x0[1] - o[:, 1]) / rn.b) ** 2 - (1.0 + rn.margin)
        return float(h.min())

    def _failure(self, x0, xbar, ubar, status, iters, t_start, slots, real) -> MPCResult:
        """A failed solve: the iterate is kept (and shifted), the command is the reference's zero command."""
        self.n_failures += 1
        p = self.vehicle
        period = self.config.control_dt or self.config.ts
        if self.numerics.zero_command_on_failure:
            u = np.array([0.0, min(max(-x0[4] / period, -p.steer_rate_max), p.steer_rate_max)])
        else:
            u = np.array([0.5 * p.a_min, min(max(-x0[4] / period, -p.steer_rate_max), p.steer_rate_max)])
        x_pred = xbar.copy()
        x_pred[:, 0] -= x_pred[0, 0]
        self._shift(xbar, ubar)
        logger.debug("reference-numerics MPC: HPIPM status %d after %d iterations; zero command", status, iters)
        return MPCResult(u=u, x_pred=x_pred, u_pred=ubar.copy(), status=STATUS_ZERO_COMMAND, success=False,
                         slack={"lat_acc": 0.0, "track": 0.0, "barrier": 0.0},
                         h_now=self._barrier_min(x0, slots, real), solve_time=time.perf_counter() - t_start,
                         qp_iterations=iters, sqp_iterations=1, barrier_slack_first=0.0, n_opponents=int(real.sum()))
