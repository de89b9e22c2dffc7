"""Environment throughput: steps per second of SOfAR-LagunaSeca-v0, one process, fixed gamma.

Usage::

    python bench/bench_env.py [--steps 1000] [--track LagunaSeca] [--rho 0.5] [--opponents 4]
                             [--gamma 0.5] [--seed 0] [--repeats 3] [--vector N] [--json PATH]
                             [--scenario paper|interactive]
                             [--compare REV [--new-stack PRESET] | --compare-stack JSON] [--rounds 5]

Two passes over the same seeded episodes:

1. plain timing of ``env.step`` (resets excluded), ``--repeats`` times over the same
   seeded steps -> steps/s (median and best pass) and per-step percentiles;
2. the same steps with timers wrapped around the components on the env's own
   instances (nothing in the package is changed): MPC (``MPCDCBF.solve``), MIQP
   (``PassingSidePlanner.plan``), track/Frenet (every public ``Track`` method, whoever
   calls it), plant (``Plant.step``), world (``Race.step`` without the plant and track
   calls inside it), observation (``observe``) and the rest (env + stack glue, reward
   terms, info). Times are exclusive: a component's time excludes the timed
   components it calls. The timers cost ~0.5 us per call. Inside these, the compiled kernels are
   timed as well (not part of the exclusive sum): the QP solver of the MPC (PIQP set-up, update
   and solve, with their Python call), its generated-C linearisation, and DAQP's branch and
   bound in the MIQP (with its data and incumbent where that is one compiled call, DAQP's C API called
   from a kernel; else ``daqp.solve``); what is left is Python (and numpy calls on small arrays).

With ``--vector N`` a third pass times a gymnasium ``AsyncVectorEnv`` of N worker
processes (the set-up ``train/pasta.py`` uses: each worker pinned to a CPU of its own, unless
``--no-pin``) and reports its total env steps/s.
With ``--compare REV`` the script instead runs an interleaved A/B against the git revision
``REV`` (see :mod:`bench_compare`, next to this script): the revision is exported into a
temporary directory, and rounds of one timed pass of the old code and one of the working
tree alternate, each in a fresh subprocess (:mod:`bench_pass`) whose ``PYTHONPATH`` selects the
package and which makes the env through the public constructor only (``gymnasium.make`` of the
registered id), so revisions from before this script's own imports run too; the medians and
spreads of the CPU time (``time.process_time``) and the wall time per step, and their ratios,
are reported, and whether both sides drove the same trajectory (a digest of every observation and
reward). With ``--new-stack PRESET`` the working tree runs that controller preset and the revision its own
default: ``--compare 2e40063 --new-stack sofar-1`` times the former default, the controller of that revision,
on the same trajectory. ``--compare-stack JSON`` runs the same A/B in the working tree between the default
controller and the controller overrides JSON (e.g. ``'{"mpc": {"qp_solver": "daqp"}}'``).

The host's 1-minute load average and the time of a fixed reference workload
(:func:`reference_workload_ms`, independent of the package) are printed and stored: on
a shared or virtual machine the same code runs slower while other tenants load the
cores, and the reference time shows by how much.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from collections import defaultdict

import numpy as np

from bench_pass import load_average, reference_workload_ms, timed_async  # the sibling each timed pass runs
from sofar_agents.cli_types import gamma_value, nonneg_float, nonneg_int, positive_int
from sofar_agents.evaluation.files import write_json_atomic
import sofar_env  # noqa: F401  (registers the ids)
from sofar_env.env import SOfARRaceEnv
from sofar_env.observation import observe
from sofar_env.scenarios import SCENARIOS
from sofar_env.stack.config import STACK_PRESETS

TRACK_METHODS = ("to_frenet", "to_cartesian", "pose", "heading", "curvature", "width_left", "width_right", "speed",
                 "wrap", "gap", "normal")


class ComponentTimer:
    """Exclusive wall time per component, for wrapped callables that may nest."""

    def __init__(self) -> None:
        self.total = defaultdict(float)
        self.calls = defaultdict(int)
        self._stack: list[list] = []

    def wrap(self, fn, component: str):
        perf = time.perf_counter
        stack = self._stack
        total, calls = self.total, self.calls

        def timed(*args, **kwargs):
            frame = [perf(), 0.0]  # start, time spent in nested timed calls
            stack.append(frame)
            try:
                return fn(*args, **kwargs)
            finally:
                stack.pop()
                elapsed = perf() - frame[0]
                total[component] += elapsed - frame[1]
                calls[component] += 1
                if stack:
                    stack[-1][1] += elapsed

        return timed


COMPILED = ("compiled: MPC QP (PIQP or DAQP)", "compiled: linearisation (generated C)", "compiled: DAQP (MIQP B&B)")


class _TimedModule:
    """A stand-in for a module whose ``solve`` is timed (the other attributes are the module's)."""

    def __init__(self, module, solve) -> None:
        self._module = module
        self.solve = solve

    def __getattr__(self, name):
        return getattr(self._module, name)


def instrument(env: SOfARRaceEnv, timer: ComponentTimer, kernels: ComponentTimer | None = None):
    """Wrap the components of a built env (after its first reset) with ``timer``; returns an undo function.

    Everything is wrapped on the env's own instances, except ``observe``, which the package's
    modules look up as a global: it is wrapped in every loaded ``sofar_env`` module that imported
    it, and the undo function restores them. ``kernels`` (optional) times the compiled kernels
    (:data:`COMPILED`): the QP solver call of the MPC and DAQP are module globals too, wrapped and
    restored the same way; the linearisation is the MPC's own instance.
    """
    undo_kernels = _instrument_kernels(env, kernels) if kernels is not None else (lambda: None)
    env.stack.mpc.solve = timer.wrap(env.stack.mpc.solve, "mpc")
    env.stack.planner.plan = timer.wrap(env.stack.planner.plan, "miqp")
    env.race.plant.step = timer.wrap(env.race.plant.step, "plant")
    env.race.step = timer.wrap(env.race.step, "world")
    for name in TRACK_METHODS:
        setattr(env.track, name, timer.wrap(getattr(env.track, name), "track/Frenet"))
    users = [m for name, m in list(sys.modules.items())
             if name.startswith("sofar_env") and getattr(m, "observe", None) is observe]
    timed_observe = timer.wrap(observe, "observation")
    for module in users:
        module.observe = timed_observe

    def undo() -> None:
        for module in users:
            module.observe = observe
        undo_kernels()

    return undo


def _instrument_kernels(env: SOfARRaceEnv, kernels: ComponentTimer):
    from sofar_env.control.mpc import backends
    from sofar_env.planning import solvers

    lin = env.stack.mpc._lin
    lin._eval = kernels.wrap(lin._eval, COMPILED[1])
    qp_call, daqp_module, bnb_kernel = backends._solve_once, solvers.daqp, solvers._bnb_solve
    backends._solve_once = kernels.wrap(qp_call, COMPILED[0])  # the MPC's QP by its backend (PIQP or DAQP)
    # the branch and bound: one compiled call (DAQP's C API from a kernel) or daqp.solve from Python
    solvers._bnb_solve = kernels.wrap(bnb_kernel, COMPILED[2])
    if daqp_module is not None:
        solvers.daqp = _TimedModule(daqp_module, kernels.wrap(daqp_module.solve, COMPILED[2]))

    def undo() -> None:
        backends._solve_once = qp_call
        solvers.daqp = daqp_module
        solvers._bnb_solve = bnb_kernel

    return undo


def run(env: SOfARRaceEnv, steps: int, gamma: float, seed: int) -> tuple[np.ndarray, dict]:
    """Step times [s] of ``steps`` env steps (resets excluded) and episode statistics."""
    action = np.array([gamma], np.float32)
    env.reset(seed=seed)
    times = np.empty(steps)
    mpc, miqp = [], []
    episodes = 0
    perf = time.perf_counter
    for i in range(steps):
        t0 = perf()
        _, _, terminated, truncated, info = env.step(action)
        times[i] = perf() - t0
        mpc.append(info["mpc_time_ms"])
        if info["miqp_time_ms"] > 0:
            miqp.append(info["miqp_time_ms"])
        if terminated or truncated:
            episodes += 1
            env.reset(seed=seed + episodes)
    return times, {"episodes_ended": episodes, "mpc_median_ms": float(np.median(mpc)),
                   "miqp_median_ms": float(np.median(miqp)) if miqp else float("nan")}


def run_vector(args: argparse.Namespace) -> dict:
    """Total env steps/s of an AsyncVectorEnv with ``args.vector`` workers, ``args.steps`` vector steps.

    Worker i runs the benchmark's env seeded ``args.seed + i``; episodes that end are reset by the
    vector env (next-step autoreset), and the steps that only reset are not counted. The workers are
    pinned to a CPU each (:mod:`sofar_env.vector`) unless ``--no-pin``, or when the package predates
    that module (older revisions: their vector env never pinned).
    """
    import functools

    factory = functools.partial(SOfARRaceEnv, track=args.track, rho=args.rho, n_opponents=args.opponents,
                                timing_info=True, **_scenario_kwargs(args))
    return timed_async(factory, args.vector, args.steps, args.gamma, args.seed, pin=not args.no_pin)


def _scenario_kwargs(args: argparse.Namespace) -> dict:
    """Keyword arguments selecting the world and the controller: none for the paper world and the default
    controller (so older revisions run too)."""
    kwargs = {} if args.scenario == "paper" else {"scenario": args.scenario}
    if args.stack != "sofar":
        kwargs["stack"] = args.stack
    return kwargs


def build_parser() -> argparse.ArgumentParser:
    """The command line of this script."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=positive_int, default=1000, help="timed env steps per pass (default 1000)")
    parser.add_argument("--track", default="LagunaSeca")
    parser.add_argument("--rho", type=nonneg_float, default=0.5)
    parser.add_argument("--opponents", type=nonneg_int, default=4)
    parser.add_argument("--gamma", type=gamma_value, default=0.5)
    parser.add_argument("--seed", type=nonneg_int, default=0)
    parser.add_argument("--repeats", type=positive_int, default=3,
                        help="timed passes over the same seeded steps (default 3): the median and the best "
                             "pass are reported; on a shared machine other load only ever adds time, so the "
                             "best pass is the closest to the code's own cost (the timeit convention)")
    parser.add_argument("--vector", type=nonneg_int, default=0, metavar="N",
                        help="also time a gymnasium AsyncVectorEnv of N worker processes (the training set-up) "
                             "and report its total env steps/s; 0 (default) skips it")
    parser.add_argument("--no-pin", action="store_true",
                        help="with --vector: leave the workers to the operating system instead of one CPU each "
                             "(sofar_env.vector, as train/pasta.py does by default)")
    parser.add_argument("--scenario", default="paper", choices=SCENARIOS,
                        help=f"the world, one of {', '.join(SCENARIOS)} (default paper)")
    parser.add_argument("--stack", default="sofar", choices=STACK_PRESETS,
                        help=f"the controller preset, one of {', '.join(STACK_PRESETS)} (default sofar)")
    parser.add_argument("--compare", default=None, metavar="REV",
                        help="interleaved A/B against the git revision REV instead of a plain run: CPU and wall "
                             "time per step, each pass in a fresh subprocess (see bench/bench_compare.py)")
    parser.add_argument("--new-stack", default=None, choices=STACK_PRESETS, metavar="PRESET",
                        help="with --compare: the working tree's side runs this controller preset, the revision "
                             "its own default (e.g. --compare 2e40063 --new-stack sofar-1: the former default, "
                             "whose trajectories the report checks against the revision's)")
    parser.add_argument("--compare-stack", default=None, metavar="JSON",
                        help="interleaved A/B in the working tree instead of a plain run: the default controller "
                             "against these controller overrides, e.g. '{\"mpc\": {\"qp_solver\": \"daqp\"}}'")
    parser.add_argument("--rounds", type=positive_int, default=5,
                        help="with --compare or --compare-stack: rounds of one pass of each side, alternating "
                             "(default 5)")
    parser.add_argument("--no-breakdown", action="store_true",
                        help="skip the instrumented pass (per-component breakdown)")
    parser.add_argument("--json", default=None, help="also write the results to this JSON file")
    return parser


def main(argv: list[str] | None = None) -> dict:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.compare is not None and args.compare_stack is not None:
        parser.error("--compare and --compare-stack are two modes: give one")
    if args.new_stack is not None and args.compare is None:
        parser.error("--new-stack is an option of --compare REV")
    if args.compare_stack is not None:
        try:
            stack = json.loads(args.compare_stack)
        except json.JSONDecodeError as exc:
            parser.error(f"--compare-stack must be a JSON object: {exc}")
        if not isinstance(stack, dict):
            parser.error("--compare-stack must be a JSON object of controller overrides")
        if args.stack != "sofar":
            parser.error("--compare-stack compares with the default controller: leave out --stack")
        from bench_compare import compare_stacks

        return compare_stacks(args, stack)
    if args.compare is not None:
        from bench_compare import compare_revisions

        return compare_revisions(args)

    def make() -> SOfARRaceEnv:
        env = SOfARRaceEnv(track=args.track, rho=args.rho, n_opponents=args.opponents, timing_info=True,
                           **_scenario_kwargs(args))
        env.reset(seed=args.seed)  # builds the controllers (and compiles them on a first run)
        for _ in range(20):  # warm-up
            env.step(np.array([args.gamma], np.float32))
        return env

    load_before = load_average()
    ref_before = reference_workload_ms()
    env = make()
    passes = [run(env, args.steps, args.gamma, args.seed) for _ in range(args.repeats)]
    ref_after = reference_workload_ms()
    load_after = load_average()
    rates = [args.steps / t.sum() for t, _ in passes]
    times, stats = passes[int(np.argsort(rates)[len(rates) // 2])]  # the median pass
    breakdown, compiled, wall = {}, {}, math.nan
    if not args.no_breakdown:
        timer, kernels = ComponentTimer(), ComponentTimer()
        env2 = make()
        undo = instrument(env2, timer, kernels)
        try:
            t0 = time.perf_counter()
            run(env2, args.steps, args.gamma, args.seed)
            wall = time.perf_counter() - t0
        finally:
            undo()
        accounted = sum(timer.total.values())
        breakdown = {k: 1e3 * v / args.steps for k, v in sorted(timer.total.items(), key=lambda kv: -kv[1])}
        breakdown["other (env + stack glue, rewards, info)"] = 1e3 * max(wall - accounted, 0.0) / args.steps
        compiled = {k: 1e3 * kernels.total.get(k, 0.0) / args.steps for k in COMPILED}

    result = {
        "track": args.track, "scenario": args.scenario, "stack": args.stack, "rho": args.rho,
        "opponents": args.opponents, "gamma": args.gamma,
        "steps": args.steps, "repeats": args.repeats, "steps_per_s": float(np.median(rates)),
        "steps_per_s_best": float(max(rates)), "steps_per_s_passes": [float(r) for r in rates],
        "step_ms": {"median": 1e3 * float(np.median(times)), "p95": 1e3 * float(np.percentile(times, 95)),
                    "mean": 1e3 * float(times.mean())},
        **stats,
        "breakdown_ms_per_step": breakdown,
        "compiled_ms_per_step": compiled,
        "instrumented_ms_per_step": 1e3 * wall / args.steps,
        "cpu_count": os.cpu_count(),
        "load_average_1min": {"before": load_before, "after": load_after},
        "reference_workload_ms": {"before": ref_before, "after": ref_after},
    }
    if args.vector:
        result["vector"] = run_vector(args)
    print(f"{args.track} ({args.scenario} world, stack {args.stack}), {args.opponents} opponents at rho={args.rho}, "
          f"gamma={args.gamma}, {args.steps} steps")
    print(f"  {result['steps_per_s']:.0f} env steps/s median of {args.repeats} passes, best "
          f"{result['steps_per_s_best']:.0f} (passes: {', '.join(f'{r:.0f}' for r in rates)})")
    if load_after is not None:
        print(f"  host load (1-min average, this run included): {load_before:.2f} before, {load_after:.2f} after, "
              f"on {os.cpu_count()} CPUs; other load only adds time")
    print(f"  host speed: reference workload {ref_before:.1f} ms before, {ref_after:.1f} ms after the passes "
          f"(a fixed CPU-bound loop, independent of the package: higher = slower host)")
    print(f"  median pass: step median {result['step_ms']['median']:.2f} ms, "
          f"p95 {result['step_ms']['p95']:.2f} ms; MPC median {stats['mpc_median_ms']:.2f} ms, "
          f"MIQP median {stats['miqp_median_ms']:.2f} ms per solve")
    if breakdown:
        print(f"  per-step breakdown (instrumented run, {result['instrumented_ms_per_step']:.2f} ms/step):")
    for name, ms in breakdown.items():
        print(f"    {name:40s} {ms:6.3f} ms  {100 * ms / result['instrumented_ms_per_step']:5.1f} %")
    if compiled:
        print("  of which compiled kernels (inside the components above):")
        for name, ms in compiled.items():
            print(f"    {name:40s} {ms:6.3f} ms  {100 * ms / result['instrumented_ms_per_step']:5.1f} %")
    if args.vector:
        vec = result["vector"]
        pin = "pinned" if vec["pinned"] else "unpinned"
        print(f"  AsyncVectorEnv, {vec['workers']} workers ({pin}): {vec['steps_per_s']:.0f} env steps/s in total "
              f"({vec['vector_steps']} vector steps, {vec['episodes_ended']} episodes ended)")
    if args.json:
        write_json_atomic(args.json, result, trailing_newline=False, indent=2)
    return result


if __name__ == "__main__":
    sys.exit(0 if main() else 1)
