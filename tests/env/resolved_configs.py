"""The resolved configuration of every stack preset, world and world x preset, single-car and multi-car.

Shared by ``tests/env/test_resolved_configs.py`` and by the command that writes the snapshot it compares
against (``python -m tests.env.resolved_configs tests/env/data/resolved_configs.json``): the snapshot was
written before the configuration layer was rebuilt, and every value must stay equal.
"""

from __future__ import annotations

import dataclasses
import json
import math
import sys
from typing import Any
from unittest import mock

MULTI_CAR_CASES: dict[str, dict[str, Any]] = {
    "side_lock0": {"race": {"side_lock": 0.0}},
    "alongside3": {"stack": {"miqp": {"alongside_gap": 3.0}}},
    "rates_all": {"race": {"lateral_rates": "all"}},
    "rates_off": {"race": {"lateral_rates": "off"}},
    "restart_inf": {"race": {"mpc_restart_slack": math.inf}},
    "restart_own": {"stack": {"mpc": {"restart_slack": 0.2}}},
    "heading0": {"race": {"heading_extent": 0.0}},
    "heading_own": {"stack": {"mpc": {"barrier": {"heading_extent": 1.0}}}},
    "dynamic_paper_mixed": {"scenario": "dynamic", "stack": "paper", "n_opponents": 2},
}
"""Multi-car races with user keys that touch the multi-car defaults (keyword arguments of the env)."""


def as_json(obj: Any) -> Any:
    """``dataclasses.asdict(obj)`` as plain JSON values (tuples as lists, inf as Infinity), without the fields
    that hold their neutral default (:func:`sofar_env.domains.neutral`: added after the snapshot, left out of
    the configuration hash at that default too)."""
    return json.loads(json.dumps(_plain(obj), default=repr, allow_nan=True))


def _plain(obj: Any) -> Any:
    """``dataclasses.asdict`` less the neutral defaults, recursively."""
    from sofar_env.domains import is_neutral_default

    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: _plain(getattr(obj, f.name)) for f in dataclasses.fields(obj)
                if not is_neutral_default(f, getattr(obj, f.name))}
    if isinstance(obj, (list, tuple)):
        return type(obj)(_plain(v) for v in obj)
    if isinstance(obj, dict):
        return {k: _plain(v) for k, v in obj.items()}
    return obj


def built_stack(env: Any) -> Any:
    """The StackConfig the core of a PettingZoo env gives its controllers (no controller is built)."""
    import sofar_env.stack as stack_module

    seen: list = []
    with mock.patch.object(stack_module, "OvertakingStack", lambda track, c, vehicle=None: seen.append(c) or c):
        env.core._make_stacks(None)
    return seen[0]


def collect() -> dict[str, dict[str, Any]]:
    """Every resolved value: ``presets`` (stack_preset), ``worlds`` (make_env_config of world/preset) and
    ``multi_car`` (the controllers' config of a two-car PettingZoo race of that world/preset, and of
    :data:`MULTI_CAR_CASES`, and of the multi-agent evaluation's race with stack overrides)."""
    import sofar_env.stack as st
    from sofar_agents.evaluation.multi_agent import RaceTask, race_env
    from sofar_agents.evaluation.protocol import Strategy
    from sofar_env.config import make_env_config
    from sofar_env.multi_agent import SOfARParallelEnv
    from sofar_env.scenarios import SCENARIOS

    out: dict[str, dict[str, Any]] = {"presets": {}, "worlds": {}, "multi_car": {}, "env_config": {}}
    for p in st.STACK_PRESETS:
        out["presets"][p] = as_json(st.stack_preset(p))
    for w in SCENARIOS:
        for p in (None, *st.STACK_PRESETS):
            kw = {"scenario": w} if p is None else {"scenario": w, "stack": p}
            key = f"{w}/{p or '-'}"
            out["worlds"][key] = as_json(make_env_config(**kw))
            out["multi_car"][key] = as_json(built_stack(SOfARParallelEnv(n_agents=2, **kw)))
    for name, kw in MULTI_CAR_CASES.items():
        env = SOfARParallelEnv(n_agents=2, **kw)
        out["multi_car"][name] = as_json(built_stack(env))
        out["env_config"][name] = as_json(dataclasses.replace(env.config, stack=built_stack(env)))
    for gap in (0.0, 8.0):
        task = RaceTask("LagunaSeca", Strategy("gamma=0.5", "fixed", 0.5), 0, cars=2, stack="paper", scenario="interactive",
                        opponents=1)
        env = race_env(task, {"pace_range": (0.8, 0.9)}, {"miqp": {"alongside_gap": gap}} if gap else None)
        out["multi_car"][f"race_env/{gap:g}"] = as_json(built_stack(env))
    return out


if __name__ == "__main__":
    with open(sys.argv[1], "w") as fh:
        json.dump(collect(), fh, indent=1, sort_keys=True)
