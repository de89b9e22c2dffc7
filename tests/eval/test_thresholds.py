"""The threshold sweep's summary: counts per (preset, gamma), the phantoms' paired effect, the edges found."""

import math

import pytest

from sofar_agents.evaluation import thresholds as th


def _row(stack, gamma, seed, success, failures=0, track="LagunaSeca", rho=0.5):
    return {"stack": stack, "strategy": f"gamma={gamma}", "seed": seed, "success": success,
            "mpc_failures": failures, "track": track, "rho": rho, "use_miqp": True}


def _sweep():
    rows = []
    for seed in range(10):
        for g, fail_from in ((0.05, 0), (0.06, 10), (0.5, 10), (0.9, 10), (0.95, 4)):
            broken = seed >= fail_from  # gamma 0.05: every episode, gamma 0.95: 6 of 10
            rows.append(_row("reference-numerics", g, seed, not broken, 3 if broken else 0))
            rows.append(_row("reference-numerics-no-phantoms", g, seed, True))
    return rows


def test_points_count_successes_and_solver_failures():
    pts = {(p.stack, p.gamma): p for p in th.sweep_points(_sweep())}
    p = pts[("reference-numerics", 0.95)]
    assert (p.episodes, p.successes, p.solver_failure_episodes, p.failed_with_solver_failure, p.mpc_failures) == \
        (10, 4, 6, 6, 18)
    assert p.success_rate == pytest.approx(0.4) and p.failure_episode_rate == pytest.approx(0.6)
    assert pts[("reference-numerics-no-phantoms", 0.05)].successes == 10


def test_phantom_effect_is_paired_per_gamma():
    eff = th.phantom_effects(_sweep(), "reference-numerics", "reference-numerics-no-phantoms")
    assert eff[0.05].n == 10 and eff[0.05].difference == pytest.approx(-1.0)
    assert eff[0.05].p_value == pytest.approx(2 * 0.5 ** 10)  # 10 discordant episodes, all one way
    assert eff[0.5].difference == 0.0 and eff[0.5].p_value == 1.0


def test_edges_bracket_the_failure_zones():
    low, high = th.failure_edges(_sweep(), "reference-numerics")
    assert low == (0.05, 0.06)          # 10 of 10 episodes against 0 of 10: p = 0.002
    assert high == (0.9, 0.95)          # 6 of 10 against 0 of 10: p = 0.031
    ex = th.failure_excess(_sweep(), "reference-numerics")
    assert ex[0.95] == (10, 6, 0, pytest.approx(2 * 0.5 ** 6))
    assert th.failure_edges(_sweep(), "reference-numerics", alpha=0.01)[1] == (None, None)
    clean = [r for r in _sweep() if r["strategy"] in ("gamma=0.5", "gamma=0.06")]
    assert th.failure_edges(clean, "reference-numerics") == ((None, None), (None, None))


@pytest.mark.parametrize("k, n, lo, hi", [(0, 20, 0.0, 0.161), (20, 20, 0.839, 1.0), (10, 20, 0.299, 0.701)])
def test_wilson_interval(k, n, lo, hi):
    a, b = th.wilson_interval(k, n)
    assert a == pytest.approx(lo, abs=1e-3) and b == pytest.approx(hi, abs=1e-3)
    assert all(math.isnan(x) for x in th.wilson_interval(0, 0))


def test_table_and_plot_are_written(tmp_path):
    pts = th.sweep_points(_sweep())
    text = th.format_sweep(pts, th.phantom_effects(_sweep(), "reference-numerics", "reference-numerics-no-phantoms"))
    assert text.count("\n") == 2 + 5 and "| 0.95 | 40 (17–69) | 6 | 6 of 6 | 100 (72–100) | 0 | -60 |" in text
    th.plot_sweep(pts, tmp_path / "sweep.png")
    assert (tmp_path / "sweep.png").stat().st_size > 10_000
