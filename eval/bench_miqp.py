"""Latency of the passing-side MIQP: DAQP branch-and-bound vs side-pattern enumeration.

Random but realistic instances: ego at 40-60 m/s, a 12 m wide track whose raceline
wanders between the edges, 1-4 opponents ahead at 75-97 % of the ego speed, near the raceline. Each
instance is planned twice with the same planner (a warm-up call 0.1 s earlier, then
the timed call), so the consistency and hysteresis terms are active as in closed
loop. Both solvers must choose the same sides and reach the same objective.

    python eval/bench_miqp.py                 # 300 instances
    python eval/bench_miqp.py -n 100 --json out.json
    python eval/bench_miqp.py --mode snapshot     # independent states, opponents alongside
    python eval/bench_miqp.py --closing-decel 10  # braking-distance window as in the stack
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys

import numpy as np

from sofar_env.planning import MIQPConfig, PassingSidePlanner

TRACK_WIDTH = 12.0   # m
CALL_DT = 0.1        # s between the warm-up and the timed call


def make_instance(rng: np.random.Generator, cfg: MIQPConfig, min_gap: float = 20.0) -> dict:
    """One scenario: ego speed, track corridor, opponents (at the warm-up time)."""
    N = cfg.nodes
    v = rng.uniform(40.0, 60.0)
    accel = rng.uniform(-1.0, 1.0)
    t = np.arange(N) * cfg.node_dt
    s_nodes = v * t + 0.5 * accel * t**2
    wavelength = rng.uniform(250.0, 600.0)
    phase = rng.uniform(0.0, 2.0 * np.pi)
    amp = rng.uniform(0.0, 3.0)

    def right_width(s):
        return TRACK_WIDTH / 2 + amp * np.sin(2 * np.pi * s / wavelength + phase)

    M = int(rng.integers(1, 5))
    s_opp = rng.uniform(min_gap, 150.0, M)
    wr = right_width(s_opp)
    # opponents race near the raceline (n = 0), sd 1.5 m, kept 1.5 m inside the edges
    n_opp = np.clip(rng.normal(0.0, 1.5, M), -wr + 1.5, TRACK_WIDTH - wr - 1.5)
    v_opp = v * rng.uniform(0.75, 0.97, M)
    wr0 = right_width(0.0)
    ego_n = float(np.clip(rng.uniform(-1.5, 1.5), -wr0 + 1.5, TRACK_WIDTH - wr0 - 1.5))
    return dict(v=v, s_nodes=s_nodes, right_width=right_width, ego_n=ego_n,
                opponents=np.column_stack([s_opp, n_opp, v_opp]))


def _call_args(inst: dict, shift: float, opponents: np.ndarray, ego_n: float) -> tuple:
    s = inst["s_nodes"]
    wr = inst["right_width"](s + shift)
    return (s, np.zeros_like(s), -wr, TRACK_WIDTH - wr, ego_n, opponents)


def run_instance(planner: PassingSidePlanner, inst: dict):
    """Snapshot mode: warm-up call, then the timed call CALL_DT later."""
    planner.reset()
    opp0 = inst["opponents"]
    planner.plan(*_call_args(inst, 0.0, opp0, inst["ego_n"]))
    progress = inst["v"] * CALL_DT
    opp1 = opp0.copy()
    opp1[:, 0] += (opp0[:, 2] - inst["v"]) * CALL_DT
    return planner.plan(*_call_args(inst, progress, opp1, inst["ego_n"]), progress=progress)


def run_rollout(planners: list, inst: dict, calls: int) -> list:
    """Rollout mode: the ego tracks the first planner's plan perfectly (its offset at the
    next call is the plan at the distance travelled), opponents move at constant speed.
    Every planner sees the same inputs; returns, per call, the list of results."""
    for p in planners:
        p.reset()
    opp = inst["opponents"].copy()
    ego_n, shift, progress = inst["ego_n"], 0.0, 0.0
    out = []
    for _ in range(calls):
        args = _call_args(inst, shift, opp, ego_n)
        res = [p.plan(*args, progress=progress) for p in planners]
        out.append(res)
        progress = inst["v"] * CALL_DT
        ego_n = float(res[0].lateral_at(progress))
        shift += progress
        opp = opp.copy()
        opp[:, 0] += (opp[:, 2] - inst["v"]) * CALL_DT
    return out


def stats_ms(times_s) -> dict:
    t = np.asarray(times_s) * 1e3
    return dict(median=float(np.median(t)), p95=float(np.percentile(t, 95)),
                mean=float(t.mean()), std=float(t.std()), max=float(t.max()))


def collect(args, cfg: MIQPConfig, solvers: tuple) -> dict:
    """Plan every instance with every solver; returns {solver: [PlanResult, ...]}."""
    rng = np.random.default_rng(args.seed)
    results = {solver: [] for solver in solvers}
    if args.mode == "snapshot":
        instances = [make_instance(rng, cfg, min_gap=5.0) for _ in range(args.instances)]
        for solver in solvers:
            planner = PassingSidePlanner(dataclasses.replace(cfg, solver=solver))
            for inst in instances[:10]:  # warm caches
                run_instance(planner, inst)
            results[solver] = [run_instance(planner, inst) for inst in instances]
    else:
        planners = [PassingSidePlanner(dataclasses.replace(cfg, solver=solver)) for solver in solvers]
        run_rollout(planners, make_instance(rng, cfg, min_gap=20.0), 5)  # warm caches
        while len(results[solvers[0]]) < args.instances:
            inst = make_instance(rng, cfg, min_gap=20.0)
            for res in run_rollout(planners, inst, args.calls):
                for solver, r in zip(solvers, res):
                    results[solver].append(r)
        for solver in solvers:
            results[solver] = results[solver][:args.instances]
    return results


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-n", "--instances", type=int, default=300)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--mode", choices=("rollout", "snapshot"), default="rollout",
                        help="rollout: short closed-loop-like sequences (default); snapshot: "
                             "independent random states, opponents possibly alongside (stress)")
    parser.add_argument("--calls", type=int, default=20, help="calls per rollout")
    parser.add_argument("--repeat", type=int, default=3,
                        help="repeat the whole (deterministic) run, keep each call's minimum time")
    parser.add_argument("--closing-decel", type=float, default=0.0,
                        help="MIQPConfig.closing_decel [m/s^2] (the stack uses the barrier's a_brake; "
                             "default 0: plain box window)")
    parser.add_argument("--json", metavar="PATH", help="also write the numbers as JSON")
    args = parser.parse_args(argv)

    cfg = MIQPConfig(closing_decel=args.closing_decel)
    solvers = ("daqp", "enumerate")
    runs = [collect(args, cfg, solvers) for _ in range(max(1, args.repeat))]
    results = runs[0]
    # per-call minimum over identical repeats: filters out preemption by other processes
    times = {solver: np.min([[r.solve_time for r in run[solver]] for run in runs], axis=0)
             for solver in solvers}

    report = {"instances": args.instances, "seed": args.seed, "mode": args.mode,
              "repeat": args.repeat, "closing_decel": args.closing_decel}
    print(f"MIQP latency over {args.instances} plan() calls, {args.mode} mode (ms)")
    print(f"{'solver':<10} {'median':>8} {'p95':>8} {'mean':>8} {'std':>8} {'max':>8}")
    for solver, res in results.items():
        st = stats_ms(times[solver])
        report[solver] = st
        print(f"{solver:<10} {st['median']:8.3f} {st['p95']:8.3f} {st['mean']:8.3f} "
              f"{st['std']:8.3f} {st['max']:8.3f}")

    bnb, enum = results["daqp"], results["enumerate"]
    side_mismatch = [i for i, (a, b) in enumerate(zip(bnb, enum)) if not np.array_equal(a.sides, b.sides)]
    obj_mismatch = [i for i, (a, b) in enumerate(zip(bnb, enum))
                    if not abs(a.objective - b.objective) <= 1e-6 * max(1.0, abs(b.objective))]
    failures = sum(not r.success for r in bnb) + sum(not r.success for r in enum)
    binaries = np.array([r.n_binaries for r in bnb])
    report.update(side_mismatch=len(side_mismatch), objective_mismatch=len(obj_mismatch),
                  failures=failures, with_slack=int(sum(r.max_slack > 0 for r in bnb)),
                  binaries_histogram={int(k): int((binaries == k).sum()) for k in np.unique(binaries)})
    print(f"same sides: {len(bnb) - len(side_mismatch)}/{len(bnb)}, same objective: "
          f"{len(bnb) - len(obj_mismatch)}/{len(bnb)}, failures: {failures}, "
          f"plans using slack: {report['with_slack']}, binaries: {report['binaries_histogram']}")
    if args.json:
        with open(args.json, "w", encoding="utf-8") as fh:
            json.dump(report, fh, indent=2)
    if side_mismatch or obj_mismatch or failures:
        print(f"MISMATCH: sides {side_mismatch[:10]}, objective {obj_mismatch[:10]}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
