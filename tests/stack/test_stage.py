"""The MPC's per-stage look-up (sofar_env.stack.stage) against the track's and the edges' own accessors, bit for
bit."""

from __future__ import annotations

import numpy as np
import pytest

from sofar_env.stack.edges import TrackEdges
from sofar_env.stack.stage import StageLookup
from sofar_env.vehicle import AV21


@pytest.mark.parametrize("footprint", [True, False])
def test_the_stage_rows_are_those_of_the_accessors(tracks, footprint):
    track = tracks["LagunaSeca"]
    L = track.length
    edges = TrackEdges(track, AV21, footprint_aware=footprint)
    lookup = StageLookup(track, edges, speed_factor=0.93)
    rng = np.random.default_rng(3)
    # the start line from both sides, a knot, the far end of a lap, and anywhere
    starts = [0.0, -0.0, L - 1e-9, L, 2.0 * L - 3.0, -1e-14, float(track.table("v")[0][7]), *rng.uniform(0.0, L, 30)]
    for ego_s in starts:
        for v in (0.0, 12.5, 61.0):
            s_rel = v * np.linspace(0.0, 1.5, 21) + rng.normal(0.0, 1e-3, 21) * (v > 0.0)
            s_abs, kappa, v_ref, n_min, n_max = lookup(ego_s, s_rel)
            want_s = ego_s + s_rel
            want = (want_s, np.asarray(track.curvature(want_s), float), 0.93 * np.asarray(track.speed(want_s), float),
                    *edges(want_s))
            for got, ref in zip((s_abs, kappa, v_ref, n_min, n_max), want, strict=True):
                assert got.tobytes() == ref.tobytes(), (ego_s, v)


def test_the_stack_stage_data_keep_their_edges_and_references(tracks):
    """The controller's stage data: the plan's lateral reference and the tightened MPC edges, as before."""
    from sofar_env.stack import OvertakingStack

    track = tracks["LagunaSeca"]
    stack = OvertakingStack(track)
    stage = stack.stage_data(100.0)
    s_abs = 100.0 + stack.mpc.predicted_s()
    np.testing.assert_array_equal(stage.kappa, track.curvature(s_abs))
    np.testing.assert_array_equal(stage.n_ref, 0.0)
    np.testing.assert_array_equal(stage.n_min, stack.edges(s_abs)[0])
