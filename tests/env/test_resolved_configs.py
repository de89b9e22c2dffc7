"""Every preset, world and multi-car race resolves to the values it had before the configuration layer was
rebuilt (the snapshot in ``data/resolved_configs.json``, written by :mod:`.resolved_configs`).

The snapshot was re-written on purpose when the default moved, and only then. To ``"sofar-4"``: every entry of
``"sofar"`` and of the default (``env_config``, the multi-car cases) gained the four stall-fix fields and nothing
else, each ``"sofar-1"`` entry equals the former ``"sofar"`` one and each new ``"sofar"`` entry the former
``"sofar-4"`` one, in every world, single-car and multi-car. To ``"sofar-6"``: the same entries gained
``mpc.qp_fallback = "daqp"`` and ``restart_buffer_edge = 0.05`` and nothing else, each new ``"sofar"`` entry
equal to the former ``"sofar-6"`` one. To ``"sofar-13"``: the same entries gained ``follow_queue = True``,
``miqp.free_plan = "smooth"`` and ``restart_buffer_scale = 0.25`` (and ``mpc.barrier.heading_extent = 2.45`` where
a case had turned the multi-car widening off, ``heading0``: the controller's own value now) and nothing else, each
new ``"sofar"`` entry and each default world entry equal to the former ``"sofar-13"`` one. To ``"sofar-17"``: the
same 37 entries gained ``mpc.qp_solver = "daqp"``, ``miqp.daqp_cycle_tol = 100`` and ``mpc.barrier.heading_sides =
"toward"`` and lost ``mpc.qp_fallback = "daqp"`` (no fallback backend: its neutral value) and nothing else, each new
``"sofar"`` entry equal to the ``"sofar-17"`` one. A new preset adds its
entries (``"sofar-5"``: 7, every other entry
unchanged; ``"sofar-7"`` and ``"sofar-8"``: 7 each, every other entry unchanged; ``"sofar-9"``, ``"sofar-10"``,
``"sofar-11"``, ``"sofar-12"``, ``"sofar-13"`` and ``"sofar-14"``: 11 each, one per world in each group), a new
world its own
(``"interactive-2"`` and ``"dynamic-2"``: 32 each, every other entry unchanged)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from .resolved_configs import collect

SNAPSHOT = json.loads((Path(__file__).parent / "data" / "resolved_configs.json").read_text())
NOW = collect()


@pytest.mark.parametrize("group", sorted(SNAPSHOT))
def test_every_resolved_config_equals_the_snapshot(group):
    assert sorted(NOW[group]) == sorted(SNAPSHOT[group])
    for name, value in SNAPSHOT[group].items():
        assert NOW[group][name] == value, f"{group}/{name}"
