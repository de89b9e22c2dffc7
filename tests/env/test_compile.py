"""Compiling the per-step kernels ahead of time (``sofar_env.compile``) and the one log line of a compilation."""

from __future__ import annotations

import logging
import math
import subprocess
import sys

import numba
import pytest

import sofar_env  # noqa: F401  (registers the ids)
from sofar_env import _jit
from sofar_env.compile import QP_SOLVERS, main, warm_up, world_of
from sofar_env.scenarios import SCENARIOS


def test_warm_up_races_a_few_steps_of_every_world() -> None:
    times = warm_up(SCENARIOS)
    assert set(times) == {*SCENARIOS, "multi-agent", *QP_SOLVERS}
    assert all(math.isfinite(t) and t > 0.0 for t in times.values())
    assert set(warm_up(["paper"], multi_agent=False, qp_solvers=())) == {"paper"}
    with pytest.raises(ValueError, match="valid worlds"):
        warm_up(["moon"])


def test_the_command_line_logs_each_world(caplog) -> None:
    with caplog.at_level(logging.INFO, logger="sofar_env.compile"):
        main(["--worlds", "paper", "--no-multi-agent"])
    assert any("paper world: kernels ready in" in r.getMessage() for r in caplog.records)
    assert any("MPC QP solver daqp: kernels ready in" in r.getMessage() for r in caplog.records)


@pytest.mark.parametrize("call", ['warm_up([], multi_agent=False)',  # the backend's own race: {"daqp": ...}
                                  'warm_up(["paper"], multi_agent=False, qp_solvers=())'])  # the default's MPC
def test_warm_up_compiles_the_daqp_condensing_kernel(call) -> None:
    """The DAQP backend's condensing kernel is compiled (or loaded from the cache) by the warm-up: by the race with
    the MPC on DAQP, and by a world's races, whose default controller (``"sofar-17"``) solves its MPC with DAQP (a
    fresh process each: no kernel loaded before)."""
    code = f"""
from sofar_env.compile import warm_up
from sofar_env.control.mpc import condensed
assert not condensed._condense.signatures
times = {call}
assert set(times) in ({{"daqp"}}, {{"paper"}}), times
assert condensed._condense.signatures, "not compiled by the warm-up"
"""
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    with pytest.raises(ValueError, match="solvers with kernels: daqp"):
        warm_up([], multi_agent=False, qp_solvers=["osqp"])


def test_warm_up_compiles_the_planners_kernels() -> None:
    """The passing-side planner's compiled calls (the problem's build, DAQP's branch and bound through its C API,
    the finish) are compiled (or loaded from the cache) by the paper world's warm-up (a fresh process)."""
    code = """
from sofar_env.compile import warm_up
from sofar_env.planning import build, daqp_c, solvers
kernels = [build.build_problem, build.finish_plan] + ([solvers._bnb_solve] if daqp_c.AVAILABLE else [])
assert not any(k.signatures for k in kernels)
warm_up(["paper"], multi_agent=False, qp_solvers=())
assert all(k.signatures for k in kernels), [k.__name__ for k in kernels if not k.signatures]
"""
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]


def test_the_first_compilation_in_a_process_logs_one_line(caplog, monkeypatch) -> None:
    def fresh(x):
        return x + 1.0

    def other(x):
        return 2.0 * x

    for fn in (fresh, other):
        fn.__module__ = "sofar_env._test_kernels"  # a kernel of the package (not cached: compiled on each call)
    monkeypatch.setattr(_jit._NOTICE, "said", False)
    with caplog.at_level(logging.INFO, logger="sofar_env.compile"):
        assert numba.njit(fresh)(1.0) == 2.0
        assert numba.njit(other)(1.0) == 2.0
        numba.njit(lambda x: x)(1.0)  # not the package's: no line either way
    notices = [r for r in caplog.records if r.getMessage() == _jit.COMPILE_NOTICE]
    assert len(notices) == 1 and notices[0].levelno == logging.INFO


def test_world_of_an_id() -> None:
    assert world_of("SOfAR-LagunaSeca-v0") == "paper"
    assert world_of("SOfAR-Monza-Interactive-v0") == "interactive"
    assert world_of("SOfAR-Monza-v0", {"scenario": "dynamic"}) == "dynamic"
    assert world_of("SOfAR-Monza-v0", {"config": {"scenario": "interactive"}}) == "interactive"
    assert world_of("CartPole-v1") is None and world_of("NoSuchEnv-v0") is None
