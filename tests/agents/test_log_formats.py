"""Numbers in log lines and reprs read as written: no ``-0.000``, no float32 noise such as ``0.3100000023841858``."""

from __future__ import annotations

import numpy as np

from sofar_agents import default_policy_path, load_policy
from sofar_agents.pasta.training_log import format_number, format_returns


def test_a_value_that_rounds_to_zero_has_no_sign() -> None:
    assert format_number(-1e-5) == "0.000" and format_number(-0.0) == "0.000"
    assert format_number(-0.0012) == "-0.001" and format_number(2.5) == "2.500" and format_number(-3.14159, 2) == "-3.14"
    line = format_returns(("safety", "barrier_margin"), np.array([-1e-7, -0.25], np.float32))
    assert line == "safety 0.000  barrier_margin -0.250"


def test_a_policy_repr_shows_its_preference_as_written() -> None:
    policy = load_policy(default_policy_path(), preference=[0.31, 0.45, 0.05, 0.04, 0.15])
    assert repr(policy).endswith("preference=[0.31, 0.45, 0.05, 0.04, 0.15])"), repr(policy)
