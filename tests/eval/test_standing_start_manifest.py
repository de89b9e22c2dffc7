"""The standing-start probe as a manifest kind: its keys are checked, a run writes rows with the manifest's hash and
exactly its placements, and committed rows are re-made bit for bit."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from sofar_agents.evaluation import manifest as mf


def _probe(out: str = "probe", **keys) -> mf.Manifest:
    base = {"name": "probe", "kind": "standing-start", "out": out, "stack": "sofar-1", "tracks": ("LagunaSeca",),
            "count": 1, "clearances": (0.5,), "drive_time": 1.0}
    return mf.Manifest(**{**base, **keys})


@pytest.mark.parametrize("keys, match", [
    ({"gammas": (0.3, 0.5)}, "one fixed gamma"),
    ({"duration": 100.0}, "drive_time"),
    ({"count": 0}, "count"),
    ({"count": 2.5}, "count"),
    ({"clearances": (-0.1,)}, "clearances"),
    ({"clearances": (float("nan"),)}, "clearances"),
    ({"clearances": ()}, "clearances"),
    ({"drive_time": 0.0}, "drive_time"),
    ({"min_distance": float("inf")}, "min_distance"),
    ({"prefix": "x"}, "prefix"),
])
def test_bad_probe_keys_are_refused(keys, match):
    with pytest.raises(ValueError, match=match):
        _probe(**keys)


def test_a_probe_manifest_reads_from_toml(tmp_path):
    path = tmp_path / "probe.toml"
    path.write_text('kind = "standing-start"\nout = "x"\nstack = "sofar-6"\nclearances = [0.3, 0.15]\ncount = 4\n')
    m = mf.load_manifest(path)
    assert (m.clearances, m.count, m.csv_name) == ((0.3, 0.15), 4, "standing_start.csv")
    assert [s.name for s in m.strategies(tmp_path)] == ["gamma=0.50"]


def test_a_probe_run_holds_its_placements_under_its_hash_and_re_makes_them(tmp_path):
    m = _probe()
    mf.run_manifest(m, tmp_path)
    folder = tmp_path / "probe"
    rows = mf.raw_rows(folder / m.csv_name, m.kind)
    assert len(rows) == 2 and {r["side"] for r in rows} == {"left", "right"}  # one arc length, both sides
    assert {mf.row_id(m, r) for r in rows} == mf.episode_ids(m, tmp_path)
    assert {(r["stack"], r["scenario"], r["config_hash"]) for r in rows} == {("sofar-1", "paper", m.config_hash)}
    check = mf.check_manifest(m, tmp_path)
    assert check.status == "ok" and check.rows == 2
    record = json.loads(mf.record_path(m, folder).read_text())
    assert record["config_hash"] == [m.config_hash] and record["settings"]["kind"] == "standing-start"
    assert (folder / "standing_start.md").read_text().count("`sofar-1`") == 2
    # re-made: the placement with the least distance first; a changed committed value is a difference
    shortest = min(rows, key=lambda r: mf.row_length(m, r))
    assert mf.rerun_rows(m, tmp_path, [shortest], tmp_path / "again") == []
    assert len(mf.raw_rows(tmp_path / "again" / m.csv_name, m.kind)) == 1  # only the placement asked for
    changed = {**shortest, "distance": "123.0"}
    assert any("distance" in d for d in mf.rerun_rows(m, tmp_path, [changed], tmp_path / "again2"))


def test_every_committed_probe_folder_has_its_manifest():
    root = Path(__file__).resolve().parents[2]
    outs = {mf.load_manifest(p).out for p in mf.manifest_paths(root / "experiments")
            if mf.load_manifest(p).kind == "standing-start"}
    found = (root / "results" / "standing_start").glob("**/standing_start.csv")
    folders = {str(p.parent.relative_to(root)) for p in found}
    assert folders and folders == outs
