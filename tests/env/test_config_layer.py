"""The configuration layer (sofar_env.configs): importable without the solvers, named presets and worlds as
registry entries, one resolver whose layers apply in their documented order, the multi-car defaults as a
layer below the user's keys, and a core that gives the controllers the resolved stack as it is."""

from __future__ import annotations

import dataclasses
import subprocess
import sys
from unittest import mock

import gymnasium as gym
import numpy as np
import pytest

import sofar_env
from sofar_env.config import make_env_config
from sofar_env.configs import registry
from sofar_env.configs.registry import (STACK_PRESET_REGISTRY, WORLD_REGISTRY, Entry, default_stack,
                                        register_stack_preset)
from sofar_env.configs.resolve import multi_car_overrides, resolve_env_config
from sofar_env.multi_agent import SOfARParallelEnv
from sofar_env.scenarios import SCENARIOS, scenario_overrides
from sofar_env.stack import STACK_PRESETS, StackConfig, stack_preset

HEAVY = ("casadi", "piqp", "daqp", "numba", "torch", "osqp", "sofar_env.stack", "sofar_env.control.mpc",
         "sofar_env.planning.miqp")


def test_the_config_layer_imports_no_solver():
    """Importing every module of the layer, reading the registries and building controller and world values
    loads no solver, no compiled kernel and no torch (resolving an EnvConfig checks its circuit name, which
    loads the tracks package)."""
    code = ("import sys, importlib, pkgutil, dataclasses, sofar_env.configs as c\n"
            "for m in pkgutil.iter_modules(c.__path__): importlib.import_module('sofar_env.configs.' + m.name)\n"
            "s = c.apply_overrides(c.stack_preset('paper'), c.WORLD_REGISTRY['dynamic'].value.as_overrides()['stack'])\n"
            "r = c.apply_overrides(c.RaceConfig(), {'side_lock': 3.0})\n"
            "c.apply_overrides(s, c.multi_car_overrides(r)['stack'])\n"
            f"print(','.join(m for m in {HEAVY!r} if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""


def test_presets_and_worlds_are_documented_registry_entries():
    assert STACK_PRESETS == tuple(STACK_PRESET_REGISTRY) == ("sofar", "sofar-1", "paper", "sofar-ends", "sofar-recover",
                                                            "sofar-2", "sofar-3", "sofar-4", "sofar-5", "sofar-6",
                                                            "sofar-7", "sofar-8", "sofar-9", "sofar-10", "sofar-11",
                                                            "sofar-12", "sofar-13", "sofar-14", "sofar-15",
                                                            "sofar-16", "sofar-17", "sofar-daqp", "reference-numerics",
                                                            "reference-numerics-no-phantoms")
    assert SCENARIOS == tuple(WORLD_REGISTRY) == ("paper", "interactive", "dynamic", "interactive-2", "dynamic-2")
    for name, (value, doc) in STACK_PRESET_REGISTRY.items():
        assert isinstance(value, StackConfig) and doc.strip(), name
        assert stack_preset(name) is value and stack_preset(f" {name.upper()} ") is value
    for name, (value, doc) in WORLD_REGISTRY.items():
        assert isinstance(value, registry.World) and doc.strip(), name
        assert scenario_overrides(name) == value.as_overrides()
        with pytest.raises(TypeError):
            value.overrides["race"] = {}  # read-only
    # the three meanings of "paper": a world, a controller, an observation layout, each documented
    assert "world" in WORLD_REGISTRY["paper"].doc and "controller" in STACK_PRESET_REGISTRY["paper"].doc
    assert "observation" in registry.OBSERVATION_LAYOUTS["paper"]
    assert all(word in registry.__doc__ for word in ('*world*', '*controller preset*', '*observation layout*'))
    with pytest.raises(ValueError, match="valid presets: sofar, sofar-1, paper"):
        stack_preset("bogus")


def test_a_world_override_mapping_is_fresh_at_every_call():
    first = scenario_overrides("dynamic")
    first["stack"]["speed_factor"] = 0.1
    assert scenario_overrides("dynamic")["stack"]["speed_factor"] == 0.7


def test_a_new_stack_preset_is_one_registry_entry(monkeypatch):
    slow = dataclasses.replace(stack_preset("sofar"), speed_factor=0.5, miqp_interval=3)
    monkeypatch.setitem(STACK_PRESET_REGISTRY, "slow-test", Entry(slow, "The default controller at half pace."))
    assert "slow-test" in STACK_PRESETS and STACK_PRESETS[-1] == "slow-test"
    env = gym.make("SOfAR-LagunaSeca-v0", stack="slow-test", config={"race": {"duration": 1.0}})
    assert env.unwrapped.config.stack == slow
    env.reset(seed=3)
    for _ in range(3):
        obs, reward, terminated, truncated, info = env.step(np.array([0.5], np.float32))
        assert np.all(np.isfinite(obs)) and np.isfinite(reward)
    assert env.unwrapped.stack.config == slow
    env.close()
    # the world's controller settings apply on top of it, as on every preset
    assert make_env_config(scenario="dynamic", stack="slow-test").stack.speed_factor == 0.7


def test_register_stack_preset_refuses_a_name_in_use_or_a_value_that_is_no_stack_config(monkeypatch):
    monkeypatch.setattr(registry, "STACK_PRESET_REGISTRY", dict(STACK_PRESET_REGISTRY))
    register_stack_preset("fresh", StackConfig(use_miqp=False), "doc")
    assert registry.STACK_PRESET_REGISTRY["fresh"].value.use_miqp is False
    with pytest.raises(ValueError, match="already registered"):
        register_stack_preset("paper", StackConfig(), "doc")
    with pytest.raises(TypeError):
        register_stack_preset("other", {"use_miqp": False}, "doc")
    with pytest.raises(ValueError, match="lower-case"):
        register_stack_preset("Upper", StackConfig(), "doc")


def test_the_layers_apply_in_their_order():
    # world, then preset (the world's controller settings on top of it), then the user's keys, then shortcuts
    assert make_env_config(scenario="dynamic", stack="paper").stack.speed_factor == 0.7
    assert make_env_config(scenario="dynamic", stack={"speed_factor": 0.6}).stack.speed_factor == 0.6
    assert make_env_config(scenario="dynamic", stack={"speed_factor": 0.6}, speed_factor=0.5).stack.speed_factor == 0.5
    cfg = make_env_config({"stack": "paper", "scenario": "interactive"}, observation="paper")
    assert cfg.stack.follow is False and cfg.race.sensor.enabled and cfg.observation == "paper"
    # an EnvConfig given as config= is the base: world and user keys still apply on top of it
    base = make_env_config(stack="sofar-ends", decision_interval=2)
    cfg = make_env_config(base, scenario="dynamic", rho=0.3)
    assert (cfg.stack.mpc.track_rows, cfg.decision_interval, cfg.stack.speed_factor, cfg.rho) == ("ends", 2, 0.7, 0.3)


def test_multi_car_defaults_are_a_layer_below_the_users_keys():
    default = resolve_env_config(None, {}, multi_car=True)
    assert (default.stack.miqp.alongside_gap, default.stack.lateral_prediction_plan, default.stack.mpc.restart_slack,
            default.stack.mpc.barrier.heading_extent, default.n_opponents) == (6.0, False, 0.05, 2.45, 0)
    # the user's own values win, 0 and inf included (no value means "unset")
    own = resolve_env_config(None, {"stack": {"miqp": {"alongside_gap": 0.0}, "lateral_prediction_plan": True,
                                              "mpc": {"restart_slack": np.inf, "barrier": {"heading_extent": 0.0}}},
                                    "n_opponents": 2}, multi_car=True)
    assert (own.stack.miqp.alongside_gap, own.stack.lateral_prediction_plan, own.stack.mpc.restart_slack,
            own.stack.mpc.barrier.heading_extent, own.n_opponents) == (0.0, True, np.inf, 0.0, 2)
    # the race fields the layer reads are the user's too; a field that is off adds nothing
    off = resolve_env_config(None, {"race": {"side_lock": 0.0, "lateral_rates": "all", "mpc_restart_slack": np.inf,
                                             "heading_extent": 0.0}}, multi_car=True)
    assert off.stack == default_stack()
    assert multi_car_overrides(off.race) == {"race": {"opponents": {"n_opponents": 0}}, "stack": {}}
    # with a preset, the layer applies on top of it, the preset's own settings elsewhere kept
    paper = resolve_env_config(None, {"stack": "paper", "scenario": "dynamic"}, multi_car=True)
    assert paper.stack.follow is False and paper.stack.speed_factor == 0.7 and paper.stack.miqp.alongside_gap == 6.0
    # single-car configurations never get it
    assert make_env_config().stack == default_stack()


def test_the_pettingzoo_env_runs_the_resolved_config_and_the_core_rewrites_nothing():
    env = SOfARParallelEnv(n_agents=2, stack={"mpc": {"barrier": {"heading_extent": 0.0}}})
    assert env.config.stack.mpc.barrier.heading_extent == 0.0 and env.config.stack.miqp.alongside_gap == 6.0
    seen = []
    import sofar_env.stack as stack_module

    with mock.patch.object(stack_module, "OvertakingStack", lambda track, c, vehicle=None: seen.append(c) or c):
        env.core._make_stacks(None)
    assert seen == [env.config.stack] * 2
    # the core itself gives any config's stack as it is, whatever the number of cars
    from sofar_env.core import ControlledRace

    seen.clear()
    core = ControlledRace(make_env_config(), n_cars=3)
    with mock.patch.object(stack_module, "OvertakingStack", lambda track, c, vehicle=None: seen.append(c) or c):
        core._make_stacks(None)
    assert seen == [default_stack()] * 3
    # the rewards and the observation measure the controller's own barrier, without the multi-car widening: the
    # default's (widened with the heading error itself since "sofar-13", 0 before), or the user's
    assert env.core.measured_barrier.heading_extent == 0.0
    assert SOfARParallelEnv(n_agents=2).core.measured_barrier == default_stack().mpc.barrier
    assert SOfARParallelEnv(n_agents=2, stack="sofar-6").core.measured_barrier.heading_extent == 0.0
    assert sofar_env.parallel_env(n_agents=2, stack={"mpc": {"barrier": {"heading_extent": 1.0}}}
                                  ).core.measured_barrier.heading_extent == 1.0
