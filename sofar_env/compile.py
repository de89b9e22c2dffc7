"""Compile and cache the per-step kernels ahead of time: ``python -m sofar_env.compile``.

The per-step loops of the environments are compiled with numba on first use and cached on
disk (:mod:`sofar_env._jit`): the first step of a fresh install takes tens of seconds per
world, later processes load the machine code in milliseconds. :func:`warm_up` takes that
first step ahead of time, for CI jobs, cluster jobs (run it once per node and install) and
the scripts of this repository, which call it before their progress bars so that no
estimate of the remaining time includes the compilation.

Usage::

    python -m sofar_env.compile                       # every world
    python -m sofar_env.compile --worlds paper        # only the paper world
    python -m sofar_env.compile --qp-solvers          # without the optional QP backends' kernels

A warm-up races short races per world on one circuit, with opponents close enough for
every part of the controller to run (the MPC's barrier rows, the passing-side planner), and
changes nothing else: the environments built afterwards behave exactly as without it. The
MPC's QP backends that have kernels of their own (:data:`QP_SOLVERS`: DAQP's condensing,
``MPCConfig.qp_solver="daqp"``) are compiled by one more short race each, in the first world
warmed up; the default controller's MPC runs on DAQP, so the worlds' races compile it already
and that race only loads it (PIQP, the backend of ``"sofar-13"`` and before, has no kernels of
its own).
"""

from __future__ import annotations

import argparse
import logging
import time
from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np

from .scenarios import SCENARIOS

__all__ = ["WARM_UP_RACES", "QP_SOLVERS", "warm_up", "world_of", "main"]

logger = logging.getLogger(__name__)

WARM_UP_RACES: tuple[tuple[float, ...], ...] = ((12.0, 25.0, 40.0, 300.0), (12.0, 25.0, 40.0, 55.0), (15.0,))
"""Opponent gaps ahead of the ego [m] of the warm-up races: every opponent in the MPC's window, then one."""
_STEPS = 3
"""Control steps per warm-up race."""
QP_SOLVERS: tuple[str, ...] = ("daqp",)
"""The MPC's QP backends (``MPCConfig.qp_solver``) with kernels of their own, which the warm-up compiles by a race
with the MPC on each: ``"daqp"``, the condensing of :mod:`sofar_env.control.mpc.condensed` (the default
controller's backend, so also compiled by any world's race)."""


def _race(track: str, world: str, gaps: tuple[float, ...], **kwargs: Any) -> None:
    """A few control steps of one warm-up race with opponents at ``gaps`` ahead."""
    from .env import SOfARRaceEnv

    opponents = {"n_opponents": len(gaps), "gaps": gaps, "offsets": (0.0, 1.0, -1.0, 0.0)}
    env = SOfARRaceEnv(track=track, scenario=world, race={"duration": 1.0, "opponents": opponents}, **kwargs)
    env.reset(seed=0)
    for _ in range(_STEPS):
        env.step(np.array([0.5], np.float32))
    env.close()


def warm_up(worlds: Iterable[str] = SCENARIOS, track: str = "LagunaSeca", multi_agent: bool = True,
            qp_solvers: Iterable[str] = QP_SOLVERS) -> dict[str, float]:
    """Compile (or load from the cache) the per-step kernels of ``worlds`` by racing a few steps of each.

    ``multi_agent`` adds a few steps of a 2-car PettingZoo race (the kernels only several controlled
    cars use); ``qp_solvers`` (of :data:`QP_SOLVERS`) a short race per QP backend with the MPC on that
    backend, in the first of ``worlds`` (the paper world where none is given). Returns the wall time per
    world (and ``"multi-agent"``, and per QP backend, e.g. ``"daqp"``) [s]: tens of seconds where the
    kernels were compiled, well under one second where they were cached. The first kernel compiled in
    a process logs one INFO line (:mod:`sofar_env._jit`).
    """
    worlds, qp_solvers = list(worlds), list(qp_solvers)
    for world in worlds:
        if world not in SCENARIOS:
            raise ValueError(f"unknown world {world!r}; valid worlds: {', '.join(SCENARIOS)}")
    for solver in qp_solvers:
        if solver not in QP_SOLVERS:
            raise ValueError(f"no kernels to compile for QP solver {solver!r}; solvers with kernels: "
                             f"{', '.join(QP_SOLVERS)}")
    times: dict[str, float] = {}
    for world in worlds:
        t0 = time.perf_counter()
        for gaps in WARM_UP_RACES:
            _race(track, world, gaps)
        times[world] = time.perf_counter() - t0
    for solver in qp_solvers:
        t0 = time.perf_counter()
        _race(track, worlds[0] if worlds else "paper", WARM_UP_RACES[0], stack={"mpc": {"qp_solver": solver}})
        times[solver] = time.perf_counter() - t0
    if multi_agent:
        from .multi_agent import parallel_env

        t0 = time.perf_counter()
        race = parallel_env(track=track, n_agents=2, config={"race": {"duration": 1.0}})
        race.reset(seed=0)
        for _ in range(_STEPS):
            race.step({agent: np.array([0.5], np.float32) for agent in race.agents})
        race.close()
        times["multi-agent"] = time.perf_counter() - t0
    return times


def world_of(env_id: str, env_kwargs: Mapping[str, Any] | None = None) -> str | None:
    """The world (``scenario``) of the registered SOfAR id ``env_id`` made with ``env_kwargs``; None for an id
    that is not registered or not a SOfAR environment."""
    import gymnasium as gym

    try:
        spec = gym.spec(env_id)
    except gym.error.Error:
        return None
    if not str(spec.entry_point).startswith("sofar_env."):
        return None
    kwargs = {**spec.kwargs, **dict(env_kwargs or {})}
    config = kwargs.get("config")
    scenario = kwargs.get("scenario", config.get("scenario") if isinstance(config, Mapping) else None)
    scenario = "paper" if scenario is None else str(scenario).strip().lower()
    return scenario if scenario in SCENARIOS else None


def main(argv: list[str] | None = None) -> dict[str, float]:
    parser = argparse.ArgumentParser(prog="python -m sofar_env.compile", description=__doc__.splitlines()[0])
    parser.add_argument("--worlds", nargs="+", choices=SCENARIOS, default=list(SCENARIOS),
                        help=f"worlds to compile, of {', '.join(SCENARIOS)} (default: all)")
    parser.add_argument("--track", default="LagunaSeca", help="circuit of the warm-up races (default LagunaSeca)")
    parser.add_argument("--no-multi-agent", action="store_true", help="leave out the PettingZoo race")
    parser.add_argument("--qp-solvers", nargs="*", choices=QP_SOLVERS, default=list(QP_SOLVERS),
                        help=f"optional MPC QP backends whose kernels to compile, of {', '.join(QP_SOLVERS)} "
                             "(default: all; none after the flag: none)")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    times = warm_up(args.worlds, track=args.track, multi_agent=not args.no_multi_agent, qp_solvers=args.qp_solvers)
    for name, seconds in times.items():
        label = (f"{name} world" if name in SCENARIOS else "multi-agent" if name == "multi-agent"
                 else f"MPC QP solver {name}")
        logger.info("%s: kernels ready in %.1f s", label, seconds)
    return times


if __name__ == "__main__":
    main()
