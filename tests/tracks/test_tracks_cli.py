"""Tests of the command line ``python -m sofar_env.tracks build|info`` (sofar_env.tracks.__main__)."""

from __future__ import annotations

import pytest
from synthetic_circuits import R, circle, write_edges

from sofar_env.tracks import Track
from sofar_env.tracks.__main__ import main as cli_main


def test_cli_build_and_info(tmp_path, capsys):
    src = tmp_path / "circle.csv"
    write_edges(src, circle(R - 1.5, 150), circle(R + 1.5, 170))
    out = tmp_path / "Cli"
    with pytest.warns(UserWarning):
        assert cli_main(["build", str(src), "--name", "Cli", "--out", str(out), "--top-speed", "20"]) == 0
    for fname in ("raceline.csv", "left_edge.csv", "right_edge.csv", "centerline.csv", "meta.json"):
        assert (out / fname).is_file()
    track = Track.load(out)
    assert track.name == "Cli" and track.max_speed == pytest.approx(20.0)
    assert cli_main(["info", str(out)]) == 0
    assert "Cli" in capsys.readouterr().out
