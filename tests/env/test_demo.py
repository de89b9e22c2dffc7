"""The demo script: footprint gap geometry and a short smoke run."""

import numpy as np
import pytest

from sofar_env.demo import footprint_gap, main
from sofar_env.geometry import footprint_corners
from sofar_env.vehicle import AV21


@pytest.mark.parametrize("dx, dy, expected", [(10.0, 0.0, 10.0 - AV21.length), (0.0, 3.0, 3.0 - AV21.width),
                                              (4.0, 0.0, 0.0), (6.9, 2.9, None)])
def test_footprint_gap(dx, dy, expected):
    a = footprint_corners(0.0, 0.0, 0.0, AV21)
    b = footprint_corners(dx, dy, 0.0, AV21)
    if expected is None:  # corner to corner
        expected = np.hypot(dx - AV21.length, dy - AV21.width)
    assert footprint_gap(a, b) == pytest.approx(expected)
    assert footprint_gap(b, a) == pytest.approx(expected)


def test_demo_smoke(tmp_path, capsys):
    out = tmp_path / "demo.gif"
    summary = main(["--seconds", "2", "--out", str(out), "--seed", "1"])
    assert out.stat().st_size > 0 and summary.video == str(out)
    assert summary.steps == 20 and summary.sim_time_s == pytest.approx(2.0)
    assert summary.collisions == 0 and summary.off_tracks == 0
    assert 0.0 < summary.closest_footprint_gap_m <= summary.closest_centre_m
    printed = capsys.readouterr().out
    for word in ("overtakes", "closest approach", "smallest barrier", "slack", "collisions", "off-tracks", "laps",
                 "MPC", "MIQP"):
        assert word in printed


def test_demo_shows_a_progress_bar_unless_told_not_to(capsys):
    main(["--seconds", "1", "--no-video"])
    err = capsys.readouterr().err
    assert "racing" in err and "/10" in err  # 10 control steps
    main(["--seconds", "1", "--no-video", "--no-progress"])
    assert "racing" not in capsys.readouterr().err
