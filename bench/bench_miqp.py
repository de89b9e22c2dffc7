"""Latency of the passing-side MIQP: DAQP branch-and-bound (with and without its incumbent) vs side-pattern
enumeration.

Random but realistic instances: ego at 40-60 m/s, a 12 m wide track whose raceline
wanders between the edges, 1-4 opponents ahead at 75-97 % of the ego speed, near the raceline. Each
instance is planned twice with the same planner (a warm-up call 0.1 s earlier, then
the timed call), so the consistency and hysteresis terms are active as in closed
loop. Both solvers must choose the same sides and reach the same objective. The branch-and-bound runs
twice: as configured (``daqp``: starting from the incumbent of ``MIQPConfig.incumbent``) and without the
incumbent (``daqp-plain``); the two must return the same plans to the bit.

    python bench/bench_miqp.py                 # 300 instances
    python bench/bench_miqp.py -n 100 --json out.json
    python bench/bench_miqp.py --mode snapshot     # independent states, opponents alongside
    python bench/bench_miqp.py --closing-decel 10  # braking-distance window as in the stack
    python bench/bench_miqp.py --from-env paper --steps 3000   # the branch-and-bound calls of the env

``--from-env WORLD`` times the problems the stack's planner hands to DAQP in a seeded closed loop of
``SOfAR-LagunaSeca-v0`` (``paper`` or ``interactive`` world, 4 opponents at ``--rho``, gamma 0.5): the run
records them, then each is solved with and without the incumbent, alternating which goes first, ``--repeat``
times (each call's minimum time is kept); the two must return the same values to the bit.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys

import numpy as np

from sofar_agents.cli_types import nonneg_float, nonneg_int, positive_int
from sofar_agents.evaluation.files import write_json_atomic
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


def collect(args, configs: dict) -> dict:
    """Plan every instance with every configuration; returns {name: [PlanResult, ...]}."""
    rng = np.random.default_rng(args.seed)
    solvers = tuple(configs)
    cfg = configs[solvers[0]]
    results = {solver: [] for solver in solvers}
    if args.mode == "snapshot":
        instances = [make_instance(rng, cfg, min_gap=5.0) for _ in range(args.instances)]
        for solver in solvers:
            planner = PassingSidePlanner(configs[solver])
            for inst in instances[:10]:  # warm caches
                run_instance(planner, inst)
            results[solver] = [run_instance(planner, inst) for inst in instances]
    else:
        planners = [PassingSidePlanner(configs[solver]) for solver in solvers]
        run_rollout(planners, make_instance(rng, cfg, min_gap=20.0), 5)  # warm caches
        while len(results[solvers[0]]) < args.instances:
            inst = make_instance(rng, cfg, min_gap=20.0)
            for res in run_rollout(planners, inst, args.calls):
                for solver, r in zip(solvers, res):
                    results[solver].append(r)
        for solver in solvers:
            results[solver] = results[solver][:args.instances]
    return results


def env_problems(world: str, steps: int, seed: int, rho: float) -> list:
    """(SideProblem, w_slack) of every branch-and-bound call of the stack's own planner in ``steps`` seeded
    steps of SOfAR-LagunaSeca-v0 in ``world``, 4 opponents at ``rho``, gamma 0.5 (the planner instance is
    wrapped; nothing else changes)."""
    import gymnasium as gym

    import sofar_env  # noqa: F401  (registers the ids)
    from sofar_env.planning import solvers

    kwargs = {} if world == "paper" else {"scenario": world}
    env = gym.make("SOfAR-LagunaSeca-v0", n_opponents=4, rho=rho, **kwargs).unwrapped
    env.reset(seed=seed)  # builds the stack
    planner = env.stack.planner
    captured = []

    def recorded(prob):
        captured.append((prob, planner.config.w_slack))
        return solvers.solve_branch_and_bound(prob, planner.config.w_slack, planner._bnb_cache)

    planner._solve_bnb = recorded
    action = np.array([0.5], np.float32)
    episode = seed
    for _ in range(steps):
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            episode += 1
            env.reset(seed=episode)
    env.close()
    return captured


def bench_from_env(args) -> int:
    """``--from-env``: the env's branch-and-bound problems, with and without the incumbent."""
    import time

    from sofar_env.planning import solvers

    problems = env_problems(args.from_env, args.steps, args.seed, args.rho)
    t_with = np.full(len(problems), np.inf)
    t_plain = np.full(len(problems), np.inf)
    differ = 0
    for rep in range(args.repeat):
        for i, (prob, w_slack) in enumerate(problems):
            plain_prob = dataclasses.replace(prob, w_diag=None)
            order = (True, False) if (i + rep) % 2 == 0 else (False, True)
            out = {}
            for bounded in order:
                t0 = time.perf_counter()
                out[bounded] = solvers.solve_branch_and_bound(prob if bounded else plain_prob, w_slack, {})
                dt = time.perf_counter() - t0
                if bounded:
                    t_with[i] = min(t_with[i], dt)
                else:
                    t_plain[i] = min(t_plain[i], dt)
            if rep == 0:
                a, b = out[True], out[False]
                same = (a is None and b is None) or (a is not None and b is not None
                                                     and all(np.array_equal(x, y) for x, y in zip(a, b)))
                differ += not same
    ratio = float(t_plain.sum() / t_with.sum())
    report = {"world": args.from_env, "rho": args.rho, "steps": args.steps, "seed": args.seed,
              "calls": len(problems),
              "repeat": args.repeat, "with_incumbent": stats_ms(t_with), "without": stats_ms(t_plain),
              "speedup_total": ratio, "not_identical": differ}
    print(f"{len(problems)} branch-and-bound calls of {args.steps} steps ({args.from_env} world, rho {args.rho}), "
          f"ms per call:")
    print(f"{'':<18} {'median':>8} {'p95':>8} {'mean':>8} {'max':>8}")
    for name, key in (("with incumbent", "with_incumbent"), ("without", "without")):
        st = report[key]
        print(f"{name:<18} {st['median']:8.3f} {st['p95']:8.3f} {st['mean']:8.3f} {st['max']:8.3f}")
    print(f"total time without / with the incumbent: {ratio:.2f}x; identical to the bit: "
          f"{len(problems) - differ}/{len(problems)}")
    if args.json:
        write_json_atomic(args.json, report, trailing_newline=False, indent=2)
    return 1 if differ else 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-n", "--instances", type=positive_int, default=300)
    parser.add_argument("--seed", type=nonneg_int, default=0)
    parser.add_argument("--mode", choices=("rollout", "snapshot"), default="rollout",
                        help="rollout: short closed-loop-like sequences (default); snapshot: "
                             "independent random states, opponents possibly alongside (stress)")
    parser.add_argument("--calls", type=positive_int, default=20, help="calls per rollout")
    parser.add_argument("--repeat", type=positive_int, default=3,
                        help="repeat the whole (deterministic) run, keep each call's minimum time")
    parser.add_argument("--closing-decel", type=nonneg_float, default=0.0,
                        help="MIQPConfig.closing_decel [m/s^2] (the stack uses the barrier's a_brake; "
                             "default 0: plain box window)")
    parser.add_argument("--from-env", choices=("paper", "interactive"),
                        help="time the branch-and-bound calls of a closed loop of the env in this world, with "
                             "and without the incumbent (instead of the random instances)")
    parser.add_argument("--steps", type=positive_int, default=3000, help="env steps of --from-env")
    parser.add_argument("--rho", type=nonneg_float, default=0.5,
                        help="opponents' pace of --from-env (bench/bench_env.py's default; the env's is 0.3)")
    parser.add_argument("--json", metavar="PATH", help="also write the numbers as JSON")
    args = parser.parse_args(argv)
    if args.from_env:
        return bench_from_env(args)

    cfg = MIQPConfig(closing_decel=args.closing_decel)
    configs = {"daqp": cfg, "daqp-plain": dataclasses.replace(cfg, incumbent=False),
               "enumerate": dataclasses.replace(cfg, solver="enumerate")}
    solvers = tuple(configs)
    runs = [collect(args, configs) for _ in range(args.repeat)]
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
    plain = results["daqp-plain"]
    not_identical = [i for i, (a, b) in enumerate(zip(bnb, plain))
                     if not (np.array_equal(a.d, b.d) and np.array_equal(a.sides, b.sides))]
    ratio_mean = report["daqp-plain"]["mean"] / report["daqp"]["mean"]
    ratio_median = report["daqp-plain"]["median"] / report["daqp"]["median"]
    report.update(incumbent_not_identical=len(not_identical), incumbent_speedup_mean=ratio_mean,
                  incumbent_speedup_median=ratio_median)
    print(f"incumbent: plans identical to the bit {len(bnb) - len(not_identical)}/{len(bnb)}; "
          f"time without / with it: {ratio_mean:.2f}x (means), {ratio_median:.2f}x (medians)")
    print(f"same sides: {len(bnb) - len(side_mismatch)}/{len(bnb)}, same objective: "
          f"{len(bnb) - len(obj_mismatch)}/{len(bnb)}, failures: {failures}, "
          f"plans using slack: {report['with_slack']}, binaries: {report['binaries_histogram']}")
    if args.json:
        write_json_atomic(args.json, report, trailing_newline=False, indent=2)
    if side_mismatch or obj_mismatch or failures or not_identical:
        print(f"MISMATCH: sides {side_mismatch[:10]}, objective {obj_mismatch[:10]}, with and without the "
              f"incumbent {not_identical[:10]}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
