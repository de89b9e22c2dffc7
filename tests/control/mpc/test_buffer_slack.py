"""The buffer slack of the end rows (``MPCConfig.track_buffer``, ``StackConfig.restart_buffer_edge``): a second
slack of the four end rows, bounded by the buffer's width and cheaper than the track slack. Off (0) it leaves the
QP as it was; on, the RTI agrees with the IPOPT reference of the same problem on both QP backends, the cheap
slack is used first, and the edge beyond it costs what it did."""

import dataclasses
import math

import numpy as np
import pytest

from sofar_env.control.mpc import MPCConfig, MPCDCBF
from sofar_env.control.mpc.layout import N_FIXED
from sofar_env.errors import ConfigError
from sofar_env.stack import stack_preset
from sofar_env.stack.config import StackConfig
from sofar_env.stack.controller import _buffer_width
from sofar_env.vehicle import AV21

from .scenarios import make_stage

# at 6 m/s, 3 m left and turned 0.5 rad towards the left edge, pulled further left: no plan keeps the front end
# inside the margin (the scene of test_end_rows.py), so the rows' slacks are active
X0 = np.array([0.0, 3.0, 0.5, 6.0, 0.0])
STAGE = make_stage(v_ref=10.0, n_ref=5.5, half_width=6.0)


@pytest.mark.parametrize("kwargs, match", [
    ({"track_buffer": 0.2}, "end rows"),  # the reference point's rows have no buffer slack
    ({"track_buffer": 1.2, "track_rows": "ends"}, "track_margin"),
    ({"track_buffer": 2.0, "track_rows": "ends"}, "track_margin"),
    ({"track_buffer": -0.1, "track_rows": "ends"}, "track_buffer"),
    ({"track_buffer": math.nan, "track_rows": "ends"}, "track_buffer"),
    ({"track_buffer": math.inf, "track_rows": "ends"}, "track_buffer"),
    ({"track_buffer_slack": (2e3, 0.0)}, "track_buffer_slack"),
    ({"track_buffer_slack": (-1.0, 2e4)}, "track_buffer_slack"),
])
def test_bad_buffer_settings_are_refused(kwargs, match):
    with pytest.raises(ConfigError, match=match):
        MPCConfig(**kwargs)


@pytest.mark.parametrize("kwargs, match", [
    ({"restart_buffer_edge": 0.05}, "restart mode"),
    ({"restart_buffer_edge": 0.05, "restart_lateral_weight": 15.0}, "end rows"),
    ({"restart_buffer_edge": -0.05, "restart_lateral_weight": 15.0, "slow_rows_speed": 10.0}, "restart_buffer_edge"),
    ({"restart_buffer_edge": math.nan, "restart_lateral_weight": 15.0, "slow_rows_speed": 10.0}, "restart_buffer_edge"),
])
def test_bad_stack_buffer_settings_are_refused(kwargs, match):
    with pytest.raises(ConfigError, match=match):
        StackConfig(**kwargs)


def test_the_buffer_is_the_margin_less_the_half_width_and_the_edge_kept():
    cfg = stack_preset("sofar-6")
    assert cfg.restart_buffer_edge == 0.05 and cfg.mpc.track_margin == 1.2
    assert _buffer_width(cfg, AV21) == pytest.approx(1.2 - 0.5 * AV21.width - 0.05)
    wide = dataclasses.replace(cfg, mpc=dataclasses.replace(cfg.mpc, track_margin=2.2))  # the dynamic world's
    assert _buffer_width(wide, AV21) == pytest.approx(2.2 - 0.5 * AV21.width - 0.05)
    assert _buffer_width(dataclasses.replace(cfg, restart_buffer_edge=0.5), AV21) == 0.0  # no band left
    assert _buffer_width(stack_preset("sofar-5"), AV21) == 0.0  # off


def test_only_the_restart_mode_has_the_buffer():
    from sofar_env.stack import OvertakingStack
    from sofar_env.tracks import Track

    stack = OvertakingStack(Track.load("LagunaSeca"), stack_preset("sofar-6"))
    assert stack._restart_mpc.config.track_buffer == pytest.approx(0.2)
    assert stack.mpc.config.track_buffer == 0.0 and stack._slow_mpc.config.track_buffer == 0.0


def _solve(cache_dir, iterations=15, **kwargs):
    cfg = MPCConfig(control_dt=0.0, cache_dir=cache_dir, track_rows="recoverable", **kwargs)
    mpc = MPCDCBF(cfg)
    for _ in range(iterations):
        res = mpc.solve(X0, STAGE, np.zeros((0, 3)), 0.5)
        assert res.success
    return mpc, res


def test_off_the_qp_is_the_one_without_the_option(cache_dir):
    """track_buffer = 0 builds the same QP as before the option: no extra column, the same plan to the bit."""
    plain, res_plain = _solve(cache_dir, iterations=3)
    off, res_off = _solve(cache_dir, iterations=3, track_buffer=0.0, track_buffer_slack=(1.0, 1.0))
    qs_plain, qs_off = (next(iter(m._qp.values())) for m in (plain, off))
    assert qs_off.nb == qs_plain.nb and not qs_off.buf
    np.testing.assert_array_equal(res_off.x_pred, res_plain.x_pred)
    np.testing.assert_array_equal(res_off.u_pred, res_plain.u_pred)


def test_on_one_bounded_column_per_stage_relaxes_the_four_end_rows(cache_dir):
    mpc, _ = _solve(cache_dir, iterations=1, track_buffer=0.2)
    qs = next(iter(mpc._qp.values()))
    assert qs.buf and qs.nb == N_FIXED + int(qs.lat) + 1 + 1 + qs.m  # (lat), track, buffer, DCBF
    col = qs.col_buf
    scale = qs.slack_scale[col - N_FIXED]
    assert scale == pytest.approx(1.0 / math.sqrt(2e4))
    np.testing.assert_allclose(qs.xu_buf[:, col] * scale, 0.2)
    np.testing.assert_array_equal(qs.xl_buf[:, col], 0.0)
    np.testing.assert_allclose(qs.c_buf[:, col], 2e3 * scale)
    g = qs.G.tocsc()
    for k in range(qs.nz // qs.nb):
        j = k * qs.nb + col
        rows = g.indices[g.indptr[j]:g.indptr[j + 1]]
        np.testing.assert_array_equal(rows, k * qs.nr + qs.row_trk + np.arange(4))
        np.testing.assert_allclose(g.data[g.indptr[j]:g.indptr[j + 1]], [-scale, scale, -scale, scale])


@pytest.mark.parametrize("qp_solver", ["piqp", "daqp"])
def test_the_rti_matches_the_ipopt_reference(cache_dir, qp_solver):
    """The scene's front end ends up beyond the margin by more than the buffer: IPOPT on the same problem (its own
    buffer variable, bounded by the buffer) finds the same plan and the same violation."""
    mpc, res = _solve(cache_dir, track_buffer=0.2, qp_solver=qp_solver)
    ref = mpc.solve_converged(X0, STAGE, np.zeros((0, 3)), 0.5)
    assert ref.success
    np.testing.assert_allclose(res.x_pred, ref.x_pred, atol=1e-5)
    assert res.slack["track"] == pytest.approx(ref.slack["track"], abs=1e-5) and res.slack["track"] > 0.2
    assert any(q.buf for q in mpc._qp.values())
