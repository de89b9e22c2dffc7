"""Analytic checks of the dynamic single-track model and its plant."""

import math

import numpy as np
import pytest

from sofar_env.dynamics import AV21_DYNAMIC, DynamicParams, DynamicPlant, casadi_dynamics, dynamic_rhs, pacejka
from sofar_env.vehicle import AV21, cartesian_rhs, rk4_step

P, V = AV21_DYNAMIC, AV21
LF, LR, L = V.wheelbase - V.lr, V.lr, V.wheelbase
M, G = P.mass, P.gravity


def _aero(vx):
    """(drag, downforce) [N] at forward speed vx."""
    q = 0.5 * P.air_density * vx * vx
    return q * P.drag_area, q * P.lift_area


def _loads(vx, a):
    """(Fz_f, Fz_r) [N]: static + downforce + longitudinal load transfer."""
    _, lift = _aero(vx)
    transfer = M * a * P.cg_height / L
    return (M * G * LR / L + P.aero_front * lift - transfer,
            M * G * LF / L + (1.0 - P.aero_front) * lift + transfer)


def _hold_speed(plant, x, v_target, delta_dot, mu, steps):
    """Run with a proportional speed loop; yields the state after every step."""
    for _ in range(steps):
        v = math.hypot(x[3], x[4])
        x = plant.step(x, (2.0 * (v_target - v), delta_dot), mu)
        yield x


def test_parameters_validate_and_share_the_kinematic_geometry():
    assert LF == pytest.approx(1.6785) and LR == pytest.approx(1.2933)
    assert 750.0 <= P.mass <= 815.11 and 800.0 <= P.yaw_inertia <= 1000.0
    assert 0.04 <= P.tau_steer <= 0.06
    lo, hi = P.mu_range
    assert 0.0 < lo < hi <= 1.0
    with pytest.raises(Exception):
        P.mass = 700.0  # frozen
    for bad in ({"mass": 0.0}, {"aero_front": 1.5}, {"v_blend_low": 6.0, "v_blend_high": 3.0},
                {"mu_range": (1.0, 0.5)}, {"lift_area": -1.0}, {"yaw_rate_gain": -1.0}):
        with pytest.raises(ValueError):
            DynamicParams(**bad)


def test_pacejka_peak_is_one_at_the_documented_slip():
    alphas = np.linspace(0.0, 0.5, 5001)
    f = np.array([pacejka(a, P.B_f, P.C_f, P.E_f) for a in alphas])
    assert f.max() == pytest.approx(1.0, abs=1e-6)
    assert math.degrees(alphas[f.argmax()]) == pytest.approx(5.8, abs=0.2)
    assert pacejka(-0.05, P.B_f, P.C_f, P.E_f) == pytest.approx(-pacejka(0.05, P.B_f, P.C_f, P.E_f))


def test_casadi_evaluation_equals_the_math_evaluation():
    f = casadi_dynamics()
    rng = np.random.default_rng(3)
    for vx in (0.0, 1.5, 4.2, 5.9, 20.0, 55.0, 88.0):  # kinematic, blend and dynamic regions
        for _ in range(3):
            x = [rng.normal(0, 50), rng.normal(0, 50), rng.uniform(-3, 3), vx, rng.normal(0, 1),
                 rng.normal(0, 0.3), rng.uniform(-0.25, 0.25), rng.uniform(-0.25, 0.25), rng.uniform(-10, 3)]
            u = [rng.uniform(-10, 3), rng.uniform(-0.35, 0.35)]
            mu = rng.uniform(0.5, 1.0)
            np.testing.assert_allclose(np.array(f(x, u, mu)).ravel(), dynamic_rhs(x, u, mu),
                                       rtol=1e-12, atol=1e-9)
    # with the yaw-rate loop on, too
    p_loop = DynamicParams(yaw_rate_gain=2.0)
    f_loop = casadi_dynamics(p_loop)
    x = [5.0, -3.0, 0.2, 40.0, 0.3, 0.1, 0.01, 0.02, -1.0]
    np.testing.assert_allclose(np.array(f_loop(x, [0.5, 0.1], 0.9)).ravel(), dynamic_rhs(x, [0.5, 0.1], 0.9, p_loop),
                               rtol=1e-12, atol=1e-9)
    # the RK4 discretisation equals the plant where no clipping acts
    plant = DynamicPlant()
    F = casadi_dynamics(dt=plant.dt, substeps=plant.substeps)
    x = plant.initial_state(10.0, -5.0, 0.4, 45.0, 0.02)
    np.testing.assert_allclose(np.array(F(x, [1.0, -0.1], 0.9)).ravel(), plant.step(x, (1.0, -0.1), 0.9),
                               rtol=1e-12, atol=1e-10)


def test_steady_cornering_matches_the_linear_bicycle_with_understeer():
    """delta = L/R + K_us a_y with K_us = m lr / (L C_f) - m lf / (L C_r), C_i = B C D Fz_i."""
    plant = DynamicPlant()
    v0, delta = 40.0, 0.005
    x = plant.initial_state(0.0, 0.0, 0.0, v0, delta)
    for x in _hold_speed(plant, x, v0, 0.0, 1.0, 150):
        pass
    vx, r = x[3], x[5]
    assert abs(dynamic_rhs(x, (x[8], 0.0), 1.0)[5]) < 1e-5  # steady
    radius, a_y = vx / r, vx * r
    assert 1.0 < a_y < 3.0  # linear range (peak is ~17 m/s^2)
    fz_f, fz_r = _loads(vx, x[8])
    drag, _ = _aero(vx)
    c_f = P.B_f * P.C_f * P.D_f * fz_f
    # the rear also delivers the drag-compensating drive force: friction ellipse
    c_r = P.B_r * P.C_r * P.D_r * fz_r * math.sqrt(1.0 - ((M * x[8] + drag) / (P.D_x * fz_r)) ** 2)
    k_us = M * LR / (L * c_f) - M * LF / (L * c_r)
    assert k_us > 0.0  # the rear-biased downforce makes the car understeer at speed
    assert L / radius + k_us * a_y == pytest.approx(delta, rel=0.01)
    assert abs(L / radius - delta) > 0.05 * delta  # the understeer term matters (test can fail)


@pytest.mark.parametrize("mu", [1.0, 0.85])
def test_lateral_acceleration_saturates_at_the_front_axle_grip(mu):
    """In a slowly tightening circle a_y = vx r peaks where the front axle reaches mu D Fz_f.

    Quasi-steady: F_yf cos(delta) lf = F_yr lr and m a_y = F_yf cos(delta) + F_yr, so a front-limited
    peak is mu D_f Fz_f cos(delta) L / (m lr), with Fz_f including downforce and load transfer.
    """
    plant = DynamicPlant()
    v0 = 50.0
    x = plant.initial_state(0.0, 0.0, 0.0, v0)
    best, at = -1.0, None
    for x in _hold_speed(plant, x, v0, 0.005, mu, 240):  # delta_cmd 0 -> 0.12 rad over 24 s
        a_y = x[3] * x[5]
        if a_y > best:
            best, at = a_y, x.copy()
    assert x[3] * x[5] < best - 0.5  # past the peak the front slides: a_y falls (understeer)
    assert DynamicPlant.lateral_acceleration(at) == pytest.approx(best, rel=0.01)
    fz_f, fz_r = _loads(at[3], at[8])
    front_limited = mu * P.D_f * fz_f * math.cos(at[6]) * L / (M * LR)
    rear_limited = mu * P.D_r * fz_r * L / (M * LF)
    assert front_limited < rear_limited
    assert best == pytest.approx(front_limited, rel=0.005)
    _, lift = _aero(at[3])
    assert best < mu * P.D_f * (G + lift / M)  # below the whole-car bound with downforce
    assert best > 1.15 * mu * P.D_f * G  # and well above the bound without it


def _steady_yaw_rate(plant, v0, delta):
    x = plant.initial_state(0.0, 0.0, 0.0, v0, delta)
    for x in _hold_speed(plant, x, v0, 0.0, 1.0, 150):
        pass
    assert abs(dynamic_rhs(x, (x[8], 0.0), 1.0, plant.params)[5]) < 1e-5  # steady
    return x


@pytest.mark.parametrize("v0", [25.0, 60.0])
def test_yaw_rate_loop_brings_the_yaw_rate_to_the_kinematic_bicycle(v0):
    """Steady cornering at delta_cmd: the loop with gain K cuts the understeer's yaw-rate error.

    Linear analysis: with the car's steady yaw gain g (v/L) (g < 1 understeer) and the servo aimed at
    delta_cmd + K (L/v) (r_ref - r), the steady r / r_ref is g (1 + K) / (1 + K g), so the relative error
    1 - r / r_ref falls from 1 - g to (1 - g) / (1 + K g).
    """
    delta = 0.004
    plain = _steady_yaw_rate(DynamicPlant(), v0, delta)
    looped = _steady_yaw_rate(DynamicPlant(DynamicParams(yaw_rate_gain=2.0)), v0, delta)
    r_ref = math.hypot(plain[3], plain[4]) * math.tan(delta) / (L * math.sqrt(1 + (LR / L * math.tan(delta)) ** 2))
    g = plain[5] / r_ref
    assert 0.5 < g < 0.98  # the plain car understeers (test can fail)
    predicted = g * 3.0 / (1.0 + 2.0 * g)
    r_ref_loop = math.hypot(looped[3], looped[4]) * math.tan(delta) / (L * math.sqrt(1 + (LR / L * math.tan(delta)) ** 2))
    assert looped[5] / r_ref_loop == pytest.approx(predicted, abs=0.01)
    assert abs(1 - looped[5] / r_ref_loop) < 0.5 * abs(1 - g)
    assert looped[6] > delta  # the servo steers more than commanded to get there
    assert looped[7] == pytest.approx(delta)  # the commanded angle itself is the MPC's


def test_low_speed_reproduces_the_kinematic_bicycle():
    """Below v_blend_low the plant is vehicle.cartesian_rhs driven by the lagged actual delta and a."""
    plant = DynamicPlant()
    controls = [(0.5, 0.2)] * 10 + [(-0.3, -0.2)] * 20 + [(0.2, 0.1)] * 10  # |delta_cmd| <= 0.2

    def augmented(s, u):  # (x, y, psi, v, delta, delta_cmd, a)
        kin = cartesian_rhs(s[:5], [s[6], (s[5] - s[4]) / P.tau_steer], V)
        return kin + [u[1], (u[0] - s[6]) / P.tau_accel]

    x = plant.initial_state(1.0, 2.0, 0.3, 2.0)
    ref = [1.0, 2.0, 0.3, 2.0, 0.0, 0.0, 0.0]
    turned = 0.0
    for u in controls:
        x = plant.step(x, u, 1.0)
        ref = rk4_step(augmented, ref, u, plant.dt, substeps=20)
        assert x[3] < P.v_blend_low
        view = plant.kinematic_view(x)
        np.testing.assert_allclose(view[:4], ref[:4], atol=1e-5)  # RK4 h = 25 ms vs 5 ms
        assert x[6] == pytest.approx(ref[4], abs=5e-6) and view[4] == pytest.approx(ref[5], abs=1e-12)
        turned = max(turned, abs(ref[2] - 0.3))
    assert turned > 0.1  # the car really turned


def test_actuator_lags_reach_63_percent_in_one_time_constant():
    for tau, index, start in ((P.tau_steer, 6, [0.0, 0.0, 0.0, 30.0, 0.0, 0.0, 0.0, 0.1, 0.0]),
                              (P.tau_accel, 8, [0.0, 0.0, 0.0, 30.0, 0.0, 0.0, 0.0, 0.0, 0.0])):
        plant = DynamicPlant(dt=tau, substeps=8)
        u = (0.0, 0.0) if index == 6 else (2.0, 0.0)
        target = 0.1 if index == 6 else 2.0
        x = plant.step(np.array(start), u, 1.0)
        assert x[index] / target == pytest.approx(1.0 - math.exp(-1.0), abs=1e-4)


def test_straight_line_braking_at_a_min_and_at_the_tyre_limit():
    plant = DynamicPlant()
    x = plant.initial_state(0.0, 0.0, 0.0, 60.0)
    for _ in range(10):  # let the brake lag settle
        x = plant.step(x, (-50.0, 0.0), 1.0)
    v1 = x[3]
    x = plant.step(x, (-50.0, 0.0), 1.0)
    assert (v1 - x[3]) / plant.dt == pytest.approx(-V.a_min, rel=1e-3)  # clipped command, grip to spare

    mu = 0.5
    x = plant.initial_state(0.0, 0.0, 0.0, 30.0)
    for _ in range(10):
        x = plant.step(x, (V.a_min, 0.0), mu)
    vx0 = x[3]
    x1 = plant.step(x, (V.a_min, 0.0), mu)
    decel = (vx0 - x1[3]) / plant.dt
    vm = 0.5 * (vx0 + x1[3])
    drag, lift = _aero(vm)
    limit = (mu * P.D_x * (M * G + lift) + drag) / M  # both axles at the friction circle
    assert decel < -V.a_min
    assert decel == pytest.approx(limit, rel=0.01)
    assert abs(x1[4]) < 1e-12 and abs(x1[5]) < 1e-12  # straight stays straight


def test_braking_moves_load_to_the_front_and_uses_the_front_grip():
    """Front axle under braking: Fz_f + m |a| h / L, 54 % of the braking force, ellipse for the rest."""
    vx, delta, a, mu = 40.0, 0.02, -8.0, 1.0
    x = [0.0, 0.0, 0.0, vx, 0.0, 0.0, delta, delta, a]  # only the front axle has slip
    drag, _ = _aero(vx)
    fz_f, _ = _loads(vx, a)
    assert fz_f == pytest.approx(_loads(vx, 0.0)[0] + M * 8.0 * P.cg_height / L)
    rho = P.brake_bias_front * (M * a + drag) / (mu * P.D_x * fz_f)
    fx_f = rho * mu * P.D_x * fz_f
    fy_f = mu * P.D_f * fz_f * math.sqrt(1.0 - rho * rho) * pacejka(delta, P.B_f, P.C_f, P.E_f)
    expected = LF * (fx_f * math.sin(delta) + fy_f * math.cos(delta)) / P.yaw_inertia
    assert dynamic_rhs(x, (a, 0.0), mu)[5] == pytest.approx(expected, rel=1e-6)


def test_braking_at_the_limit_costs_lateral_grip():
    x = [0.0, 0.0, 0.0, 30.0, -1.0, 0.0, 0.0, 0.0, 0.0]  # sliding sideways at 1.9 deg
    coasting = dynamic_rhs(x, (0.0, 0.0), 0.5)
    braking = dynamic_rhs(x[:8] + [V.a_min], (V.a_min, 0.0), 0.5)
    assert coasting[4] > 3.0  # the tyres push the slide back
    assert abs(braking[4]) < 0.05 * coasting[4]  # saturated by braking: almost nothing left


def test_stops_without_reversing_and_starts_from_standstill():
    plant = DynamicPlant()
    x = plant.initial_state(0.0, 0.0, 0.0, 8.0, 0.1)
    for _ in range(40):
        x = plant.step(x, (V.a_min, 0.0), 1.0)
        assert x[3] >= 0.0
    assert x[3] == 0.0 and x[4] == 0.0 and x[5] == 0.0
    stopped = x.copy()
    x = plant.step(x, (V.a_min, 0.0), 1.0)
    np.testing.assert_array_equal(x[:6], stopped[:6])
    for _ in range(10):
        x = plant.step(x, (V.a_max, 0.0), 1.0)
    assert x[3] > 0.5 and np.isfinite(x).all()
    assert plant.kinematic_view(x)[3] == pytest.approx(math.hypot(x[3], x[4]))


def test_seeded_inputs_give_identical_trajectories():
    def run(seed):
        rng = np.random.default_rng(seed)
        plant = DynamicPlant()
        x = plant.initial_state(0.0, 0.0, 0.0, 40.0)
        mu = rng.uniform(*P.mu_range)
        out = []
        for _ in range(30):
            x = plant.step(x, (rng.uniform(-10, 3), rng.uniform(-0.35, 0.35)), mu)
            out.append(x)
        return np.array(out)

    np.testing.assert_array_equal(run(7), run(7))
    assert not np.array_equal(run(7), run(8))


def test_bad_inputs_raise():
    plant = DynamicPlant()
    x = plant.initial_state(0.0, 0.0, 0.0, 10.0)
    for u, mu, name in (((math.nan, 0.0), 1.0, "a_cmd"), ((0.0, math.inf), 1.0, "delta_dot_cmd"),
                        ((0.0, 0.0), math.nan, "mu")):
        with pytest.raises(ValueError, match=name):
            plant.step(x, u, mu)
    with pytest.raises(ValueError):
        plant.step(x, (0.0, 0.0), 0.0)
    with pytest.raises(ValueError):
        plant.step(x[:5], (0.0, 0.0), 1.0)
    with pytest.raises(ValueError):
        plant.initial_state(0.0, 0.0, 0.0, -1.0)
    with pytest.raises(ValueError):
        DynamicPlant(substeps=0)
