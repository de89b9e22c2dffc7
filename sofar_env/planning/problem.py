"""One passing-side MIQP instance: its data, the factorised cost Hessian, and its exact cost.

:class:`SideProblem` is what the planner assembles at every call and what both
solver routes (:mod:`sofar_env.planning.solvers`) read. The lateral cost

    sum_k w_dev (d_k - n_ref_k)^2 + sum_k w_smooth (d_{k+1} - d_k)^2
    [+ sum_k w_prev (d_k - d_prev_k)^2]

has the Hessian ``H_d = 2 (w_dev I + w_smooth D'D [+ w_prev I])`` (``D`` the first
difference), which depends only on the configuration; :func:`cost_factors` computes
its Cholesky factor ``H_d = R'R`` once, and the solvers work in ``u = R d`` (``d =
R^-1 u``). :func:`evaluate` gives the reported objective: the full cost at a
returned ``(d, b)`` with the minimal slack, so that the two routes are directly
comparable.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._jit import kernel
from .config import MIQPConfig

__all__ = ["SideProblem", "cost_factors", "plan_cost", "evaluate", "SLACK_TOL"]

SLACK_TOL = 1e-6
"""[m] side-constraint violations below this are solver tolerance, not slack use."""


@dataclass
class SideProblem:
    """Per-call data shared by the two solver routes."""

    lo: np.ndarray           # (N,) lower bounds on d (continuity included)
    hi: np.ndarray           # (N,) upper bounds on d
    f_d: np.ndarray          # (N,) linear cost on d (0.5 x'Hx + f'x convention)
    Rinv: np.ndarray         # (N, N) d = Rinv u
    RinvT: np.ndarray        # (N, N) its transpose (u-space cost f_u = RinvT f_d)
    pair_k: np.ndarray       # (P,) node of each active pair
    pair_c: np.ndarray       # (P,) cluster of each active pair
    pair_n: np.ndarray       # (P,) opponent offset of each active pair
    pair_w: np.ndarray       # (P,) lateral clearance required by each active pair [m]
    pair_r: np.ndarray       # (P,) relevant-opponent index of each active pair
    n_clusters: int
    f_b: np.ndarray          # (C,) linear hysteresis cost per cluster
    n_ref: np.ndarray
    d_prev: np.ndarray | None
    b_prev: np.ndarray       # (R,) previous side (1 left, 0 right, -1 unknown) per relevant opponent
    rel_cluster: np.ndarray  # (R,) cluster of each relevant opponent
    b_fixed: np.ndarray | None = None  # (C,) side a cluster is locked to (1 left, 0 right), -1 free; None: all free
    w_diag: float | None = None    # H_d = 2 (w_diag I + w_smooth D'D): w_dev [+ w_prev] [1/m^2]; None: no incumbent
    w_smooth: float = 0.0          # smoothness weight of H_d [1/m^2] (with w_diag)


def cost_factors(config: MIQPConfig) -> dict[bool, tuple[np.ndarray, np.ndarray]]:
    """``(R^-1, R^-T)`` of the lateral cost Hessian, without (False) and with (True) the
    consistency term ``w_prev``."""
    N = config.nodes
    # Hessian blocks of d: 2 * (w_dev I + w_smooth D'D [+ w_prev I]).
    D = np.diff(np.eye(N), axis=0)
    base = 2.0 * (config.w_dev * np.eye(N) + config.w_smooth * (D.T @ D))
    # Change of variables u = R d with H_d = R'R, so DAQP sees a diagonal
    # Hessian (its O(n) set-up path) and d = R^-1 u enters through fixed rows.
    factors = {}
    for key, H_d in ((False, base), (True, base + 2.0 * config.w_prev * np.eye(N))):
        R = np.linalg.cholesky(H_d).T                 # upper triangular, H_d = R'R
        Rinv = np.linalg.solve(R, np.eye(N))          # d = Rinv u
        factors[key] = (np.ascontiguousarray(Rinv), np.ascontiguousarray(Rinv.T))
    return factors


def plan_cost(config: MIQPConfig, d, n_ref, d_prev, switch_cost, slack_cost) -> float:
    """The cost of the lateral plan ``d`` plus the given switch and slack costs [-]."""
    dd = d[1:] - d[:-1]  # np.diff(d)
    val = config.w_dev * float(np.add.reduce((d - n_ref) ** 2)) + config.w_smooth * float(dd @ dd)  # (...).sum()
    if d_prev is not None:
        val += config.w_prev * float(np.add.reduce((d - d_prev) ** 2))
    return val + switch_cost + slack_cost


def evaluate(config: MIQPConfig, prob: SideProblem, d: np.ndarray, b: np.ndarray) -> tuple[float, np.ndarray]:
    """Exact cost of ``(d, b)`` with the minimal slack, and that slack per pair."""
    xi, switch = _slack_and_switch(b, d, prob.pair_c, prob.pair_k, prob.pair_n, prob.pair_w, prob.rel_cluster,
                                   prob.b_prev)
    return plan_cost(config, d, prob.n_ref, prob.d_prev, config.w_switch * switch,
                     config.w_slack * float(np.add.reduce(xi))), xi


@kernel
def _slack_and_switch(b, d, pair_c, pair_k, pair_n, pair_w, rel_cluster, b_prev):
    """(P,) the minimal slack of each active pair at ``(d, b)`` [m]: ``n + w - d_k`` passing left
    (``b_c > 0.5``), ``d_k - (n - w)`` passing right, 0 up to :data:`SLACK_TOL`; and the number of side
    switches ``sum (b - b_prev)^2`` over the relevant opponents with a previous side (``b_prev >= 0``), a
    sum of whole numbers, exact in any order. One compiled call (:mod:`sofar_env._jit`)."""
    P = pair_k.shape[0]
    xi = np.empty(P)
    for p in range(P):
        dk = d[pair_k[p]]
        x = pair_n[p] + pair_w[p] - dk if b[pair_c[p]] > 0.5 else dk - (pair_n[p] - pair_w[p])
        xi[p] = x if x > SLACK_TOL else 0.0
    switch = 0.0
    for r in range(b_prev.shape[0]):
        if b_prev[r] >= 0:
            diff = b[rel_cluster[r]] - b_prev[r]
            switch += diff ** 2
    return xi, switch
