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


class _Built(Exception):
    """Raised by the stand-in build: the command got past its argument checks."""


def _edges(tmp_path):
    src = tmp_path / "circle.csv"
    write_edges(src, circle(R - 1.5, 150), circle(R + 1.5, 170))
    return src


def _file(tmp_path):
    (tmp_path / "taken").write_text("not a circuit\n")
    return tmp_path / "taken"


def _circuit(tmp_path):
    folder = tmp_path / "Built"
    folder.mkdir()
    (folder / "meta.json").write_text("{}\n")
    return folder


# (source, out, extra options, None if the build may start, else words of the message); paths from tmp_path
BUILD_ARGUMENT_CASES = {
    "new-folder": (_edges, lambda t: t / "new" / "Cli", [], None),
    "empty-folder": (_edges, lambda t: t, [], None),
    "circuit-with-force": (_edges, _circuit, ["--force"], None),
    "out-is-a-file": (_edges, _file, [], ["--out", "taken exists and is not a folder"]),
    "out-is-a-file-even-with-force": (_edges, _file, ["--force"], ["exists and is not a folder"]),
    "out-below-a-file": (_edges, lambda t: _file(t) / "Cli", [], ["cannot create it", "is not a folder"]),
    "out-holds-a-circuit": (_edges, _circuit, [], ["already holds a circuit (meta.json)", "--force"]),
    "source-missing": (lambda t: t / "missing.csv", lambda t: t / "Cli", [], ["missing.csv: file not found"]),
    "source-is-a-folder": (lambda t: t, lambda t: t / "Cli", [], ["cannot read"]),
}


@pytest.mark.parametrize("case", sorted(BUILD_ARGUMENT_CASES))
def test_cli_build_checks_its_arguments_before_building(case, tmp_path, monkeypatch, capsys):
    """A bad input or --out ends the command at once (exit status 2, a message, no traceback), before the build."""
    import sofar_env.tracks.__main__ as cli

    def no_build(*args, **kwargs):
        raise _Built

    monkeypatch.setattr(cli, "build_track", no_build)
    source, out, extra, words = BUILD_ARGUMENT_CASES[case]
    out_path = out(tmp_path)
    argv = ["build", str(source(tmp_path)), "--name", "Cli", "--out", str(out_path), *extra]
    if words is None:
        with pytest.raises(_Built):
            cli_main(argv)
        return
    try:
        code = cli_main(argv)
    except SystemExit as exc:  # a usage error
        code = exc.code
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err
    for word in words:
        assert word in err, err
    assert not (out_path / "raceline.csv").exists()


def test_build_track_checks_the_output_folder_before_building(tmp_path, monkeypatch):
    """The library call fails as fast as the command line for an --out it cannot write."""
    from sofar_env.tracks.builder import pipeline
    from sofar_env.tracks.builder.io import OutputFolderError

    monkeypatch.setattr(pipeline, "build_from_edges", lambda *a, **k: pytest.fail("built before the check"))
    with pytest.raises(OutputFolderError, match="exists and is not a folder"):
        pipeline.build_track(_edges(tmp_path), "Cli", _file(tmp_path))
