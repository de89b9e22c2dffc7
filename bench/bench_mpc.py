"""Benchmark of the MPC-DCBF step: closed loop on a synthetic circular road.

The ego car drives at about 40 m/s on a 14 m wide ring road of constant curvature
1/200 m^-1 among four slower opponents (30-36 m/s) in three lanes; an opponent that
falls 30 m behind is respawned 110-150 m ahead in a random lane, so overtakes keep
happening. A minimal lane chooser sets the lateral reference (the MIQP's job in the
full stack). No track files are needed.

The three MPC variants run in lock-step, each in its own copy of the same world, so
machine load affects them alike:

* ``piqp+compiled``: PIQP, linearisation compiled to C (the default);
* ``piqp+casadi``: PIQP, linearisation through CasADi's own evaluation;
* ``osqp+compiled``: OSQP backend (less accurate).

Usage::

    python bench/bench_mpc.py [--steps 600] [--gamma 0.3] [--seed 0] [--json out.json]

Writes a table of per-solve wall-clock times (median, p95, mean, std in ms), QP and
SQP iterations, failures, the smallest barrier value and the number of collisions.
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
from dataclasses import dataclass, field

import numpy as np

from sofar_agents.cli_types import gamma_value, nonneg_int, positive_int
from sofar_agents.evaluation.files import write_json_atomic
from sofar_env.control import MPCConfig, MPCDCBF, MPCStageData, barrier
from sofar_env.vehicle import AV21, frenet_rhs, rk4_step

logger = logging.getLogger("bench_mpc")

KAPPA = 1.0 / 200.0
HALF_WIDTH = 7.0
LANES = (-3.5, 0.0, 3.5)
V_REF = 40.0


@dataclass
class World:
    """Ego (Frenet, absolute s) and opponents (s, n, v) on the ring road."""

    rng: np.random.Generator
    x: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 0.0, V_REF, KAPPA * AV21.wheelbase]))
    opp: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    lane: float = 0.0
    collisions: int = 0

    def __post_init__(self) -> None:
        gaps = np.array([30.0, 60.0, 95.0, 130.0])
        lanes = self.rng.choice(LANES, size=4)
        speeds = self.rng.uniform(30.0, 36.0, size=4)
        self.opp = np.column_stack([gaps, lanes, speeds])

    def relative_opponents(self) -> np.ndarray:
        rel = self.opp.copy()
        rel[:, 0] -= self.x[0]
        return rel

    def choose_lane(self) -> float:
        """Stay in the lane unless an opponent blocks it within 60 m; then take the freest lane."""
        rel = self.relative_opponents()

        def free_gap(lane: float) -> float:
            mask = (np.abs(rel[:, 1] - lane) < 2.5) & (rel[:, 0] > -8.0)
            return float(rel[mask, 0].min()) if np.any(mask) else np.inf

        if free_gap(self.lane) < 60.0:
            best = max(LANES, key=lambda ln: (min(free_gap(ln), 200.0), -abs(ln - self.x[1])))
            if min(free_gap(best), 200.0) > free_gap(self.lane) + 10.0:
                self.lane = best
        return self.lane

    def step(self, u: np.ndarray, dt: float) -> None:
        p = AV21
        a = float(np.clip(u[0], p.a_min, p.a_max))
        dd = float(np.clip(u[1], -p.steer_rate_max, p.steer_rate_max))
        x = list(self.x)
        for _ in range(4):
            x = rk4_step(lambda xx, uu: frenet_rhs(xx, uu, KAPPA, p), x, [a, dd], dt / 4, 1)
            x[3] = max(x[3], 0.0)
            x[4] = min(max(x[4], -p.steer_max), p.steer_max)
        self.x = np.array(x)
        self.opp[:, 0] += self.opp[:, 2] * dt
        rel = self.relative_opponents()
        if np.any((np.abs(rel[:, 0]) < p.length) & (np.abs(rel[:, 1] - self.x[1]) < p.width)):
            self.collisions += 1
        for i in np.flatnonzero(rel[:, 0] < -30.0):
            self.opp[i] = [self.x[0] + self.rng.uniform(110.0, 150.0), self.rng.choice(LANES),
                           self.rng.uniform(30.0, 36.0)]


def stage_data(mpc: MPCDCBF, world: World) -> MPCStageData:
    n = mpc.config.horizon + 1
    return MPCStageData(kappa=np.full(n, KAPPA), n_ref=np.full(n, world.choose_lane()), v_ref=np.full(n, V_REF),
                        n_min=np.full(n, -HALF_WIDTH), n_max=np.full(n, HALF_WIDTH))


def run(steps: int, gamma: float, seed: int) -> dict:
    variants = {
        "piqp+compiled": MPCConfig(),
        "piqp+casadi": MPCConfig(compile=False),
        "osqp+compiled": MPCConfig(qp_solver="osqp"),
    }
    mpcs = {name: MPCDCBF(cfg) for name, cfg in variants.items()}
    worlds = {name: World(np.random.default_rng(seed)) for name in variants}
    log = {name: {"t": [], "cpu": [], "qpt": [], "qp": [], "sqp": [], "m": [], "fail": 0, "h": []}
           for name in variants}
    for name, mpc in mpcs.items():  # warm-up: builds the QP structures, not timed
        if not mpc.codegen_info.compiled and variants[name].compile:
            logger.warning("%s: C compilation unavailable (%s)", name, mpc.codegen_info.message)
    for _ in range(steps):
        for name, mpc in mpcs.items():
            w = worlds[name]
            x0 = w.x.copy()
            x0[0] = 0.0
            stage, opp = stage_data(mpc, w), w.relative_opponents()
            cpu = time.thread_time()
            res = mpc.solve(x0, stage, opp, gamma)
            cpu = time.thread_time() - cpu
            rec = log[name]
            rec["t"].append(res.solve_time)
            rec["cpu"].append(cpu)
            rec["qpt"].append(res.qp_time)
            rec["m"].append(res.n_opponents)
            rec["qp"].append(res.qp_iterations)
            rec["sqp"].append(res.sqp_iterations)
            rec["fail"] += int(not res.success)
            rec["h"].append(float(barrier(w.x, w.opp).min()))
            w.step(res.u, mpc.config.control_dt)
    out = {}
    for name, rec in log.items():
        t = np.array(rec["t"][1:]) * 1e3  # the first (cold) solve is excluded
        out[name] = {
            "median_ms": float(np.median(t)), "p95_ms": float(np.percentile(t, 95)), "mean_ms": float(t.mean()),
            "std_ms": float(t.std()), "cpu_median_ms": float(np.median(rec["cpu"][1:]) * 1e3),
            "qp_median_ms": float(np.median(rec["qpt"][1:]) * 1e3), "opponents_in_qp_mean": float(np.mean(rec["m"])),
            "qp_iter_median": float(np.median(rec["qp"])),
            "qp_iter_mean": float(np.mean(rec["qp"])), "sqp_iter_mean": float(np.mean(rec["sqp"])),
            "failures": rec["fail"], "min_h": float(np.min(rec["h"])), "collisions": worlds[name].collisions,
            "distance_m": float(worlds[name].x[0]), "compiled": mpcs[name].codegen_info.compiled,
        }
    return out


def format_table(results: dict, steps: int) -> str:
    head = (f"{'variant':15s} {'median':>7s} {'p95':>7s} {'mean':>7s} {'std':>7s} {'cpu':>7s} {'in QP':>7s} "
            f"{'QP it':>6s} {'SQP it':>6s} {'opp':>5s} {'fail':>5s} {'min h':>7s} {'coll':>5s} {'dist m':>8s}")
    lines = [f"MPC-DCBF closed loop, {steps} solves per variant. Times in ms: wall clock of solve() "
             "(median, p95, mean, std), median CPU time of the thread, median time inside the QP solver; "
             "QP it = median interior-point iterations; SQP it and opp (opponents with QP rows) = means.",
             head, "-" * len(head)]
    for name, r in results.items():
        lines.append(f"{name:15s} {r['median_ms']:7.3f} {r['p95_ms']:7.3f} {r['mean_ms']:7.3f} {r['std_ms']:7.3f} "
                     f"{r['cpu_median_ms']:7.3f} {r['qp_median_ms']:7.3f} {r['qp_iter_median']:6.0f} "
                     f"{r['sqp_iter_mean']:6.2f} {r['opponents_in_qp_mean']:5.2f} {r['failures']:5d} "
                     f"{r['min_h']:7.3f} {r['collisions']:5d} {r['distance_m']:8.0f}")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=positive_int, default=600, help="solves per variant (default 600)")
    parser.add_argument("--gamma", type=gamma_value, default=0.3, help="DCBF decay (default 0.3)")
    parser.add_argument("--seed", type=nonneg_int, default=0)
    parser.add_argument("--json", metavar="PATH", help="also write the results as JSON")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    results = run(args.steps, args.gamma, args.seed)
    sys.stdout.write(format_table(results, args.steps))
    if args.json:
        report = {"steps": args.steps, "gamma": args.gamma, "seed": args.seed, "results": results}
        write_json_atomic(args.json, report, trailing_newline=False, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
