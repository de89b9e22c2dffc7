"""MPCConfig validation and time grid; the argument check of a solve."""

import numpy as np
import pytest

from sofar_env.control.mpc import MPCConfig
from sofar_env.control.mpc.types import validate_arguments

from .scenarios import N, make_stage


def test_time_grid_starts_with_the_plant_period():
    t = MPCConfig().time_grid()
    assert t.shape == (N + 1,) and t[0] == 0.0 and t[1] == pytest.approx(0.1)
    np.testing.assert_allclose(np.diff(t[1:]), 0.075)
    assert MPCConfig(control_dt=0.0).dt0 == pytest.approx(0.075)
    assert MPCConfig(first_step=0.05).time_grid()[1] == pytest.approx(0.05)


@pytest.mark.parametrize("kwargs", [dict(horizon=1), dict(ts=0.0), dict(control_dt=-0.1), dict(first_step=0.0),
                                    dict(q=(1.0, 2.0)), dict(r=(0.0, 1.0)), dict(barrier_slack=(1.0, 0.0)),
                                    dict(track_margin=-1.0), dict(max_opponents=1.5), dict(qp_solver="gurobi"),
                                    dict(cold_start_iterations=0), dict(restart_slack=0.0),
                                    dict(restart_slack=-1.0), dict(restart_slack=float("nan"))])
def test_config_rejects_malformed_values(kwargs):
    with pytest.raises(ValueError):
        MPCConfig(**kwargs)


def test_validate_arguments_copies_and_anchors():
    x0 = np.array([12.0, 0.5, 0.0, 40.0, 0.0])
    x, arrays, opp, gamma = validate_arguments(x0, make_stage(v_ref=41.0), [], 1, N)
    assert x[0] == 0.0 and x0[0] == 12.0  # a copy, with s taken as 0
    assert arrays.shape == (5, N + 1) and np.all(arrays[2] == 41.0)
    assert opp.shape == (0, 3) and gamma == 1.0


@pytest.mark.parametrize("case", ["gamma_nan", "gamma_big", "gamma_str", "x0_short", "x0_inf", "opp_shape",
                                  "opp_nan", "stage_short", "stage_type"])
def test_validate_arguments_rejects_malformed_ones(case):
    x0 = np.array([0.0, 0.0, 0.0, 40.0, 0.0])
    stage, opp, gamma = make_stage(), np.zeros((0, 3)), 0.5
    if case == "gamma_nan":
        gamma = float("nan")
    elif case == "gamma_big":
        gamma = 1.5
    elif case == "gamma_str":
        gamma = "half"
    elif case == "x0_short":
        x0 = x0[:4]
    elif case == "x0_inf":
        x0[3] = np.inf
    elif case == "opp_shape":
        opp = np.zeros((2, 2))
    elif case == "opp_nan":
        opp = np.array([[10.0, np.nan, 30.0]])
    elif case == "stage_short":
        stage = make_stage(n=N - 1)
    else:
        stage = {"kappa": np.zeros(N + 1)}
    with pytest.raises(ValueError):
        validate_arguments(x0, stage, opp, gamma, N)
