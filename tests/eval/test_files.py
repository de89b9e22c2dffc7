"""Atomic writes of result files: the target is the old file or the new one, and nothing else is left behind."""

from __future__ import annotations

import json
import os

import pytest

from sofar_agents.evaluation import files
from sofar_agents.evaluation.files import write_json_atomic, write_text_atomic


def _folder(path) -> list[str]:
    return sorted(p.name for p in path.parent.iterdir())


def test_a_write_replaces_the_file_and_creates_its_folder(tmp_path):
    target = tmp_path / "new" / "report.md"
    write_text_atomic(target, "one\n")
    write_text_atomic(target, "two\r\nlines\n")
    assert target.read_bytes() == b"two\r\nlines\n"  # written as given: no newline translation
    assert _folder(target) == ["report.md"]


def test_json_is_written_as_json_dumps_gives_it(tmp_path):
    target = tmp_path / "record.json"
    data = {"b": [1, 2.5, None], "a": "x"}
    write_json_atomic(target, data, indent=1, sort_keys=True)
    assert target.read_text() == json.dumps(data, indent=1, sort_keys=True) + "\n"
    write_json_atomic(target, data, trailing_newline=False, indent=2)
    assert target.read_text() == json.dumps(data, indent=2)


@pytest.mark.parametrize("failure", ["replace", "serialise"])
def test_a_failed_write_leaves_the_old_file_and_no_temporary_file(tmp_path, monkeypatch, failure):
    target = tmp_path / "pareto.json"
    write_text_atomic(target, "old\n")
    if failure == "replace":  # e.g. interrupted between the write and the move
        def refuse(src, dst):
            raise OSError("disk gone")

        monkeypatch.setattr(files.os, "replace", refuse)
        with pytest.raises(OSError, match="disk gone"):
            write_json_atomic(target, {"new": 1})
    else:
        with pytest.raises(TypeError):
            write_json_atomic(target, {"new": object()})
    monkeypatch.undo()
    assert target.read_text() == "old\n"
    assert _folder(target) == ["pareto.json"]
    assert not any(name.endswith(".tmp") for name in os.listdir(tmp_path))


def test_the_tables_markdown_is_written_through_it(tmp_path, monkeypatch):
    """The report writers of the evaluation use the atomic writer (a failed move leaves the old report)."""
    from sofar_agents.evaluation.results import write_markdown

    target = tmp_path / "table1.md"
    write_markdown(target, "old\n")
    monkeypatch.setattr(files.os, "replace", lambda src, dst: (_ for _ in ()).throw(OSError("no")))
    with pytest.raises(OSError):
        write_markdown(target, "new\n")
    monkeypatch.undo()
    assert target.read_text() == "old\n" and _folder(target) == ["table1.md"]


def test_a_new_file_gets_the_mode_open_gives_and_a_replaced_one_keeps_its_own(tmp_path):
    """mkstemp's temporary file is 0600; the published file is not: 0666 less the umask when new, the replaced
    file's own bits otherwise (a results folder shared by a group stays readable)."""
    old = os.umask(0o027)
    try:
        target = tmp_path / "stalls.md"
        write_text_atomic(target, "one\n")
        assert target.stat().st_mode & 0o777 == 0o640
        os.chmod(target, 0o604)
        write_text_atomic(target, "two\n")
        assert target.stat().st_mode & 0o777 == 0o604 and target.read_text() == "two\n"
    finally:
        os.umask(old)
