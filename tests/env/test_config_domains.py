"""Every configuration field declares its type and domain, checked in one place when the configuration is built.

Item by item: NaN, infinite and out-of-range values (item 15), wrong types (item 16) and a world time step that
differs from the MPC's control interval (item 13) are refused by ``gymnasium.make`` with a
:class:`~sofar_env.errors.ConfigError` naming the key, before any episode runs.
"""

import math

import gymnasium as gym
import numpy as np
import pytest

import sofar_env  # noqa: F401  (registers the ids)
from sofar_env.config import ConfigError, EnvConfig, RewardWeights, make_env_config
from sofar_env.control.barrier import BarrierParams
from sofar_env.control.mpc import MPCConfig
from sofar_env.domains import check_fields, domain_of, undeclared_fields
from sofar_env.dynamics import DynamicParams
from sofar_env.errors import ConfigError as ErrorsConfigError
from sofar_env.multi_agent import parallel_env
from sofar_env.opponents import DefenceConfig, LineConfig, OpponentConfig, PaceConfig, TrafficConfig
from sofar_env.planning import MIQPConfig
from sofar_env.race_config import RaceConfig
from sofar_env.sensing import SensorConfig
from sofar_env.stack import StackConfig
from sofar_env.tracks.builder import BuildConfig
from sofar_env.vehicle import VehicleParams

CONFIG_CLASSES = [EnvConfig, RewardWeights, RaceConfig, OpponentConfig, PaceConfig, LineConfig, DefenceConfig,
                  TrafficConfig, SensorConfig, VehicleParams, DynamicParams, BarrierParams, MPCConfig, MIQPConfig,
                  StackConfig, BuildConfig]

NAN, INF = math.nan, math.inf


def _nest(path: str, value) -> dict:
    """``"race.opponents.rho", v`` -> ``{"race": {"opponents": {"rho": v}}}``."""
    tree = value
    for part in reversed(path.split(".")):
        tree = {part: tree}
    return tree


def test_config_error_is_a_value_error_from_a_dependency_free_module():
    assert ConfigError is ErrorsConfigError and issubclass(ConfigError, ValueError)
    import ast

    import sofar_env.errors as errors

    imports = [n for n in ast.walk(ast.parse(open(errors.__file__).read()))
               if isinstance(n, (ast.Import, ast.ImportFrom)) and getattr(n, "module", None) != "__future__"]
    assert imports == []


@pytest.mark.parametrize("cls", CONFIG_CLASSES, ids=lambda c: c.__name__)
def test_every_field_of_every_config_class_declares_its_domain(cls):
    assert undeclared_fields(cls) == []
    check_fields(cls())  # the defaults lie in their domains


# ---------------------------------------------------------------------------------------------- item 15
@pytest.mark.parametrize("path, value", [
    ("race.opponents.overtake_threshold", NAN),
    ("race.opponents.gaps", (120.0, NAN)),
    ("race.opponents.offsets", (0.0, INF)),
    ("race.opponents.respawn_clearance", -1.0),
    ("stack.mpc.q", (0.0, NAN, 0.0, 2.5, 0.0)),
    ("stack.mpc.r", (0.01, INF)),
    ("stack.mpc.track_slack", (NAN, 6e4)),
    ("race.vehicle.steer_max", NAN),
    ("race.vehicle.steer_rate_max", INF),
    ("stack.mpc.qp_eps_abs", NAN),
    ("stack.mpc.qp_eps_abs", 0.0),
    ("stack.mpc.qp_eps_rel", -1e-9),
    ("stack.mpc.opponent_range_ahead", NAN),
    ("stack.mpc.barrier_active_tol", INF),
    ("stack.look_ahead", NAN),
    ("stack.look_behind", -5.0),
    ("stack.miqp.w_smooth", NAN),
    ("stack.miqp.cluster_gap", INF),
    ("stack.mpc.barrier.b", NAN),
    ("race.dynamic.B_f", NAN),
    ("race.dynamic.E_r", NAN),
    ("race.dynamic.E_f", 1.5),
    ("race.dynamic.mu_range", (0.8, NAN)),
    ("race.sensor.sigma_s", -1.0),
    ("race.opponents.pace.spread", NAN),
    ("race.opponents.defence.trigger", INF),
    ("race.start_s", INF),
    ("reward_weights.safety", INF),
    ("initial_gamma", NAN),
])
def test_nan_infinite_and_out_of_range_values_are_refused_at_make(path, value):
    """Item 15: each was accepted (or refused with an error that named no key) and wrecked episodes silently."""
    with pytest.raises(ConfigError) as info:
        gym.make("SOfAR-LagunaSeca-v0", config=_nest(path, value))
    assert f"{path} must be" in str(info.value), str(info.value)


# ---------------------------------------------------------------------------------------------- item 16
@pytest.mark.parametrize("kwargs, key, words", [
    ({"use_miqp": "yes"}, "stack.use_miqp", "True or False"),
    ({"use_miqp": 1}, "stack.use_miqp", "True or False"),
    ({"config": {"race": {"sensor": {"enabled": "false"}}}}, "race.sensor.enabled", "True or False"),
    ({"config": {"race": {"v2v": 0}}}, "race.v2v", "True or False"),
    ({"timing_info": "no"}, "timing_info", "True or False"),
    ({"config": {"stack": {"look_behind": None}}}, "stack.look_behind", "a finite number"),
    ({"config": {"race": {"dt": "0.1"}}}, "race.dt", "a finite number"),
    ({"rho": True}, "race.opponents.rho", "a finite number"),
    ({"config": {"reward_weights": {"safety": "10"}}}, "reward_weights.safety", "a finite number"),
    ({"offsets": ("left",)}, "race.opponents.offsets", "finite numbers"),
    ({"n_opponents": 2.5}, "race.opponents.n_opponents", "an integer"),
    ({"n_opponents": True}, "race.opponents.n_opponents", "an integer"),
    ({"decision_interval": 2.0}, "decision_interval", "an integer"),
    ({"config": {"race": {"plant_substeps": 4.0}}}, "race.plant_substeps", "an integer"),
    ({"config": {"stack": {"mpc": {"horizon": 20.0}}}}, "stack.mpc.horizon", "an integer"),
    ({"config": {"race": {"sensor": {"latency_steps": "2"}}}}, "race.sensor.latency_steps", "an integer"),
    ({"config": {"stack": {"mpc": {"qp_solver": 3}}}}, "stack.mpc.qp_solver", "one of 'piqp', 'osqp'"),
])
def test_wrong_types_are_refused_at_make_naming_the_key(kwargs, key, words):
    """Item 16: each passed ``gym.make`` and failed later naming nothing (or, ``enabled="false"``, turned the
    sensor on)."""
    with pytest.raises(ConfigError) as info:
        gym.make("SOfAR-LagunaSeca-v0", **kwargs)
    text = str(info.value)
    assert text.startswith(f"{key} must be") and words in text, text


@pytest.mark.parametrize("kwargs, read, expected", [
    ({"n_opponents": np.int64(2)}, lambda c: c.n_opponents, 2),
    ({"rho": np.float32(0.5)}, lambda c: c.rho, np.float32(0.5)),
    ({"use_miqp": np.bool_(False)}, lambda c: c.use_miqp, False),
    ({"config": {"race": {"duration": 60}}}, lambda c: c.race.duration, 60),
    ({"config": {"stack": {"mpc": {"restart_slack": math.inf}}}}, lambda c: c.stack.mpc.restart_slack, math.inf),
    ({"stall_seconds": None}, lambda c: c.stall_seconds, None),
])
def test_numpy_scalars_ints_for_floats_and_documented_inf_and_none_are_accepted(kwargs, read, expected):
    assert read(make_env_config(**kwargs)) == expected


def test_the_domain_is_declared_next_to_the_field():
    d = domain_of(RaceConfig, "dt")
    assert (d.kind, d.gt, d.unit) == ("real", 0.0, "s")
    assert domain_of(StackConfig, "use_miqp").kind == "bool"
    assert domain_of(OpponentConfig, "n_opponents").describe() == "an integer >= 0"


def test_build_config_validate_checks_the_domains():
    with pytest.raises(ConfigError, match="BuildConfig.qp_iterations must be an integer >= 1"):
        BuildConfig(qp_iterations=2.5).validate()
    with pytest.raises(ConfigError, match="BuildConfig.top_speed must be a finite number > 0"):
        BuildConfig(top_speed=True).validate()


# ---------------------------------------------------------------------------------------------- item 13
@pytest.mark.parametrize("race_dt, control_dt, ok", [
    (0.2, None, False),   # the issue: the car left the track at 8.4 s and no failure was counted
    (0.05, None, False),
    (0.1, 0.2, False),
    (0.1, 0.0, False),    # 0 disables the MPC's shift: a world that moves needs its period
    (0.2, 0.2, True),
    (0.05, 0.05, True),
    (0.1, None, True),
])
def test_race_dt_must_equal_the_mpc_control_interval(race_dt, control_dt, ok):
    config = {"race": {"dt": race_dt}}
    if control_dt is not None:
        config["stack"] = {"mpc": {"control_dt": control_dt}}
    makers = [lambda: gym.make("SOfAR-LagunaSeca-v0", config=config),
              lambda: gym.make("SOfAR-Monza-Dynamic-v0", config=config),
              lambda: parallel_env(track="LagunaSeca", n_agents=2, config=config)]
    for make in makers:
        if ok:
            env = make()
            assert env.unwrapped.config.race.dt == env.unwrapped.config.stack.mpc.control_dt == race_dt
            env.close()
        else:
            with pytest.raises(ConfigError) as info:
                make()
            assert "race.dt" in str(info.value) and "stack.mpc.control_dt" in str(info.value), str(info.value)
