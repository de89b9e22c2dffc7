"""The MPC's QP backends on the same QPs: PIQP (sparse, default) against DAQP (condensed, dense).

Records the QPs of a closed loop of ``bench/bench_mpc.py``'s ring road (PIQP in the loop), then
solves each recorded QP with both backends, interleaved (PIQP, DAQP, PIQP, ...), each keeping
one solver per pattern as in the controller, and with a tight reference (PIQP, fresh set-up,
tolerances 1e-11). Reports the per-solve CPU time (``time.thread_time``) and the largest
differences to the reference of the first input ``du_0`` and of the plan (all ``du_k``,
``dx_{k+1}``).

Usage::

    python bench/bench_qp_backends.py [--steps 300] [--gamma 0.3] [--seed 0] [--repeat 3]
"""

from __future__ import annotations

import argparse
import copy
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_mpc import World, stage_data  # noqa: E402

from sofar_agents.cli_types import gamma_value, nonneg_int, positive_int  # noqa: E402
from sofar_env.control import MPCConfig, MPCDCBF  # noqa: E402
from sofar_env.control.mpc import backends, rti  # noqa: E402


def record_qps(steps: int = 300, gamma: float = 0.3, seed: int = 0, cfg: MPCConfig | None = None) -> list[tuple]:
    """``(QPStructure copy, data copy)`` of every QP of a closed loop with the MPC of ``cfg`` (None: the default,
    PIQP)."""
    mpc = MPCDCBF(cfg or MPCConfig())
    world = World(np.random.default_rng(seed))
    qps: list[tuple] = []
    inner = rti.solve_qp

    def recording(qs, data, cfg):
        qps.append((copy.deepcopy(qs), tuple(np.array(d, copy=True) for d in data)))
        return inner(qs, data, cfg)

    rti.solve_qp = recording
    try:
        for _ in range(steps):
            x0 = world.x.copy()
            x0[0] = 0.0
            res = mpc.solve(x0, stage_data(mpc, world), world.relative_opponents(), gamma)
            world.step(res.u, mpc.config.control_dt)
    finally:
        rti.solve_qp = inner
    for qs, _ in qps:
        qs.drop_solver()
    return qps


def _fresh(qs, backend: str):
    out = copy.deepcopy(qs)
    out.drop_solver()
    out.backend = backend
    return out


def solve_all(qps: list[tuple], cfg: MPCConfig = MPCConfig()) -> dict:
    """Each QP by PIQP and DAQP (one structure per pattern each, interleaved) and by the tight reference."""
    tight = replace(cfg, qp_eps_abs=1e-11, qp_eps_rel=1e-11, qp_max_iter=500)
    own: dict = {"piqp": {}, "daqp": {}}
    out = {k: [] for k in ("piqp", "daqp", "ref", "cpu_piqp", "cpu_daqp", "it_daqp", "it_piqp")}
    for qs, data in qps:
        key = (qs.m, qs.lat, qs.trk)
        for name in ("piqp", "daqp"):
            mine = own[name].setdefault(key, _fresh(qs, name))
            mine.A.data[:] = qs.A.data  # this QP's matrices in the solver's structure
            mine.G.data[:] = qs.G.data
            t = time.thread_time()
            z, it, msg = backends.solve_qp(mine, data, cfg)
            out[f"cpu_{name}"].append(time.thread_time() - t)
            out[name].append(z)
            out[f"it_{name}"].append(it)
        ref = _fresh(qs, "piqp")
        z, _, _ = backends.solve_qp(ref, data, tight)
        out["ref"].append(z)
    return out


def accuracy(qps: list[tuple], sol: dict, name: str, other: str = "ref") -> dict:
    """Largest |difference| of ``du_0`` and of the plan between backends ``name`` and ``other``."""
    first, plan, n = 0.0, 0.0, 0
    for (qs, _), za, zb in zip(qps, sol[name], sol[other]):
        if za is None or zb is None:
            continue
        a, b = za.reshape(-1, qs.nb), zb.reshape(-1, qs.nb)
        first = max(first, float(np.abs(a[0, :2] - b[0, :2]).max()))
        plan = max(plan, float(np.abs(a[:, :7] - b[:, :7]).max()))
        n += 1
    return {"first_input": first, "plan": plan, "compared": n}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=positive_int, default=300, help="closed-loop steps recorded (default 300)")
    parser.add_argument("--gamma", type=gamma_value, default=0.3, help="DCBF decay (default 0.3)")
    parser.add_argument("--seed", type=nonneg_int, default=0)
    parser.add_argument("--repeat", type=positive_int, default=3, help="timing passes over the recorded QPs")
    args = parser.parse_args(argv)
    qps = record_qps(args.steps, args.gamma, args.seed)
    sol = solve_all(qps)
    cpu = {"piqp": [], "daqp": []}
    for _ in range(args.repeat - 1):  # further timing passes (fresh solvers each pass)
        again = solve_all(qps)
        for name in cpu:
            cpu[name].append(again[f"cpu_{name}"])
    fails = {name: sum(z is None for z in sol[name]) for name in ("piqp", "daqp", "ref")}
    print(f"{len(qps)} QPs of a {args.steps}-step closed loop (ring road, gamma {args.gamma}, seed {args.seed}); "
          f"failures {fails}")
    for name in ("piqp", "daqp"):
        t = np.array([sol[f"cpu_{name}"], *cpu[name]]).min(axis=0) * 1e6
        acc = accuracy(qps, sol, name)
        print(f"{name}: CPU per solve median {np.median(t):.0f} us, p95 {np.percentile(t, 95):.0f} us, "
              f"mean {t.mean():.0f} us (min over {args.repeat} passes); iterations median "
              f"{np.median(sol[f'it_{name}']):.0f}; vs reference: max |du_0| diff {acc['first_input']:.2e}, "
              f"max plan diff {acc['plan']:.2e} ({acc['compared']} QPs)")
    acc = accuracy(qps, sol, "daqp", "piqp")
    print(f"daqp vs piqp: max |du_0| diff {acc['first_input']:.2e}, max plan diff {acc['plan']:.2e}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
