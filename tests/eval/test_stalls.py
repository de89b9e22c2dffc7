"""The stall diagnosis: the classification rules on synthetic step records, one real replay of a stall."""

from __future__ import annotations

import csv
import dataclasses
import gzip
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from sofar_agents.evaluation import stall_rows as sr
from sofar_agents.evaluation import stalls as st
from sofar_agents.evaluation.configs import episode_config_hash

from .episode_csv import write_episode_csv

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "eval"))
import stalls as stalls_cli  # noqa: E402

# A racing step with nothing wrong: every rule's property is false.
_FREE = st.StepRecord(step=0, t=0.0, s=0.0, n=0.0, e=0.0, v=0.0, delta=0.0, decision="left", plan_status="optimal",
                      plan_slack=0.0, followed_v=math.nan, mpc_status="solved", track_slack=0.0, barrier_slack=0.0,
                      h_min=40.0, v_plan=20.0, v_next=1.5, v_ref=20.0, n_ref=0.0, accel=5.0, gap_ahead=50.0,
                      n_ahead=0.0, v_ahead=20.0, room_beside=6.0, corner_room=3.0, turn_room=2.0, row_room=2.0)


def _window(n: int = 100, **changes) -> list[st.StepRecord]:
    return [dataclasses.replace(_FREE, step=k, t=0.1 * k, **changes) for k in range(n)]


@pytest.mark.parametrize(("changes", "expected"), [
    ({"squeezed_ahead": 1.0, "gap_ahead": 5.0, "v_ahead": 0.0, "v_next": 0.0}, "squeeze_deadlock"),
    ({"mpc_status": "fallback_shift"}, "mpc_fallback"),
    ({"decision": "follow", "v_ref": 0.0, "followed_v": 0.0}, "follow_hold"),
    ({"gap_ahead": 8.0, "v_ahead": 0.0, "room_beside": 1.0}, "stopped_ahead_no_room"),
    ({"e": -0.6, "row_room": -0.05, "v_next": 0.0}, "edge_no_turn_back"),
    ({"e": -0.54, "row_room": 0.38, "v_next": 0.0, "accel": 0.0}, "zero_plan"),
    ({"v_next": 0.0, "v_ref": 0.5}, "other"),
])
def test_each_rule_by_hand(changes, expected):
    cls, ev = st.classify(_window(**changes))
    assert cls == expected
    assert ev["steps"] == st.WINDOW_STEPS


def test_rules_apply_in_order_and_by_majority():
    # behind a car the world's squeeze rule holds, every other rule gives way (rule 0 first); an old record (nan) or
    # a car that is not squeezed does not count
    held = _window(squeezed_ahead=1.0, decision="follow", v_ref=0.0, gap_ahead=8.0, v_ahead=0.0, room_beside=1.0)
    assert st.classify(held)[0] == "squeeze_deadlock" and st.classify(held)[1]["squeezed"] == 1.0
    assert st.classify(_window(squeezed_ahead=0.0, mpc_status="fallback_shift"))[0] == "mpc_fallback"
    assert st.classify(_window(mpc_status="fallback_shift"))[1]["squeezed"] == 0.0
    # a fallback loop behind a stopped car with no room is a fallback loop (rule 1 before rule 3)
    both = _window(mpc_status="fallback_brake", gap_ahead=8.0, v_ahead=0.0, room_beside=1.0)
    assert st.classify(both)[0] == "mpc_fallback"
    # a follow plan with the speed reference free is not a follow hold
    assert st.classify(_window(decision="follow", v_ref=20.0, v_next=0.0))[0] == "zero_plan"
    # a car stopped ahead with room beside it is not rule 3
    assert st.classify(_window(gap_ahead=8.0, v_ahead=0.0, room_beside=5.0))[0] == "other"
    # a property holds when it holds in at least half of the window's steps
    half = _window(50, mpc_status="fallback_shift") + _window(50)
    assert st.classify(half)[0] == "mpc_fallback"
    fewer = _window(49, mpc_status="fallback_shift") + _window(51)
    assert st.classify(fewer)[0] == "other"
    # only the window counts: earlier records (the approach) do not
    late = _window(300, mpc_status="fallback_shift") + _window(100)
    assert st.classify(late)[0] == "other"
    assert st.classify([])[0] == "other"


# opponents ahead as (gap [m], speed [m/s], squeezed) -> squeezed_ahead
QUEUES = [
    ("the car ahead squeezed and standing", [(5.0, 0.0, True)], 1.0),
    ("a standing queue led by a squeezed car", [(5.5, 0.0, False), (17.5, 0.0, False), (29.5, 0.1, True)], 1.0),
    ("the queue broken by a gap", [(5.5, 0.0, False), (30.0, 0.0, True)], 0.0),
    ("a moving car in the queue", [(5.5, 0.0, False), (17.5, 3.0, False), (29.5, 0.0, True)], 0.0),
    ("the car ahead beyond the near gap", [(16.0, 0.0, True)], 0.0),
    ("the car ahead squeezed but moving", [(5.0, 2.0, True)], 0.0),
    ("a queue without a squeezed car", [(5.0, 0.0, False), (17.0, 0.0, False)], 0.0),
    ("no car ahead (one behind)", [(-5.0, 0.0, True)], 0.0),
]


@pytest.mark.parametrize(("cars", "expected"), [q[1:] for q in QUEUES], ids=[q[0] for q in QUEUES])
def test_a_car_ahead_held_by_a_squeezed_car(cars, expected):
    from types import SimpleNamespace

    rel, v, squeezed = (np.array(x) for x in zip(*cars))
    field = SimpleNamespace(rel=rel[::-1].astype(float), v=v[::-1].astype(float), squeezed=squeezed[::-1].astype(bool))
    assert st._squeezed_ahead(field) == expected


def test_every_class_is_documented():
    doc = st.__doc__
    for cls in st.CLASSES:
        assert f"``{cls}``" in doc


def test_stalled_tasks_from_rows():
    rows = [{"track": "Monza", "strategy": "gamma=0.30", "rho": 0.1, "seed": 7, "stalled": True, "use_miqp": True,
             "duration": 200.0, "n_opponents": "8", "stack": "sofar-recover", "scenario": "interactive", "episode": 1},
            {"track": "Monza", "strategy": "gamma=0.30", "rho": 0.1, "seed": 8, "stalled": False, "use_miqp": True,
             "duration": 200.0, "n_opponents": "8", "stack": "sofar-recover", "scenario": "interactive"},
            {"track": "Monza", "strategy": "adaptive", "rho": 0.1, "seed": 9, "stalled": True, "use_miqp": True,
             "duration": 200.0, "n_opponents": "8", "stack": "sofar", "scenario": "interactive"}]
    tasks = sr.stalled_tasks(rows)
    assert len(tasks) == 1
    t = tasks[0]
    assert (t.seed, t.strategy.gamma, t.n_opponents, t.stack, t.scenario) == (7, 0.3, 8, "sofar-recover", "interactive")
    assert sr.stalled_tasks(rows, stacks=["sofar"]) == []


def test_fresh_tasks_pair_the_presets():
    tasks = sr.fresh_tasks(["sofar", "sofar-recover"], [0.05], ["Monza"], [0.1, 0.2], 2, base_seed=7301)
    assert len(tasks) == 8
    assert [t.stack for t in tasks[:2]] == ["sofar", "sofar-recover"]
    assert tasks[0].seed == tasks[1].seed and tasks[0].n_opponents == 8 and tasks[0].scenario == "interactive"


def _replay_rows(tmp_path, row):
    """Write ``row`` as a one-episode CSV, replay its stall with the script; the output folder and the rows of its
    ``stalls.csv``."""
    write_episode_csv(tmp_path / "run" / "table1_episodes.csv", [row])
    out = tmp_path / "stalls"
    assert stalls_cli.main(["--replay", str(tmp_path / "run" / "table1_episodes.csv"), "--out", str(out),
                            "--log-level", "WARNING"]) == 0
    with open(out / "stalls.csv", newline="") as f:
        return out, list(csv.DictReader(f))


def test_replay_of_a_stall(tmp_path):
    """Laguna Seca, rho 0.1, gamma 0.15 with "sofar-recover": a committed stall at 54.8 s (base seed 0), replayed
    with a 60 s horizon by the script, then re-classified from its records. A seeded run reproduces on one
    instruction set only; where the episode ends otherwise, only the files of a replay without a stall are checked."""
    row = {"track": "LagunaSeca", "rho": 0.1, "seed": 4258579602, "strategy": "gamma=0.15", "success": 0,
           "use_miqp": 1, "stalled": 1, "duration": 60.0, "n_opponents": 8, "stack": "sofar-recover",
           "scenario": "interactive"}
    out, first = _replay_rows(tmp_path, row)
    assert len(first) == 1 and first[0]["stack"] == "sofar-recover"
    assert first[0]["config_hash"] == episode_config_hash("sofar-recover", "interactive", 60.0)
    assert first[0]["restarts"] == "0"  # "sofar-recover" has no restart mode
    assert (out / "stalls.md").is_file()
    if first[0]["outcome"] != "stalled":
        assert first[0]["cls"] == "" and not (out / stalls_cli.RECORDS).exists()
        return
    assert first[0]["cls"] in st.CLASSES
    with gzip.open(out / stalls_cli.RECORDS, "rt", newline="") as f:
        records = sr.records_from_rows(csv.DictReader(f))
    (steps,) = records.values()
    assert 200 <= len(steps) <= 220  # the 20 s below 1 m/s and up to 2 s before
    assert all(r.v < st.RECORD_SPEED for r in steps) and sum(r.v >= 1.0 for r in steps) <= 20
    # --report classifies again from the records: the same class; a rerun skips the episode
    assert stalls_cli.main(["--report", str(out)]) == 0
    with open(out / "stalls.csv", newline="") as f:
        again = list(csv.DictReader(f))
    assert again[0]["cls"] == first[0]["cls"]
    assert stalls_cli.main(["--replay", str(tmp_path / "run" / "table1_episodes.csv"), "--out", str(out),
                            "--log-level", "WARNING"]) == 0
    with open(out / "stalls.csv", newline="") as f:
        assert len(list(csv.DictReader(f))) == 1
    # a stalls.csv of another version (without the config_hash column) is refused, not appended to
    old = tmp_path / "old"
    old.mkdir()
    (old / "stalls.csv").write_text("label,track,rho,seed,stack,gamma\n")
    assert stalls_cli.main(["--replay", str(tmp_path / "run" / "table1_episodes.csv"), "--out", str(old),
                            "--log-level", "WARNING"]) == 2
    assert (old / "stalls.csv").read_text() == "label,track,rho,seed,stack,gamma\n"


def test_replay_with_another_preset_and_a_csv_without_stalls(tmp_path):
    """``--replay-with`` runs the committed stalls with another preset (its name and hash in the rows); a CSV without
    a stall writes nothing and exits 0; ``--replay-with`` without ``--replay`` or with an unknown preset is refused."""
    row = {"track": "LagunaSeca", "rho": 0.1, "seed": 4258579602, "strategy": "gamma=0.15", "success": 0,
           "use_miqp": 1, "stalled": 1, "duration": 20.0, "n_opponents": 8, "stack": "sofar-recover",
           "scenario": "interactive"}
    write_episode_csv(tmp_path / "run" / "table1_episodes.csv", [row])
    out = tmp_path / "stalls"
    assert stalls_cli.main(["--replay", str(tmp_path / "run" / "table1_episodes.csv"), "--replay-with", "sofar-7",
                            "--out", str(out), "--log-level", "WARNING"]) == 0
    with open(out / "stalls.csv", newline="") as f:
        (first,) = csv.DictReader(f)
    assert first["stack"] == "sofar-7" and first["outcome"] == "success"
    assert first["config_hash"] == episode_config_hash("sofar-7", "interactive", 20.0)
    write_episode_csv(tmp_path / "none" / "table1_episodes.csv", [{**row, "stalled": 0, "success": 1}])
    assert stalls_cli.main(["--replay", str(tmp_path / "none" / "table1_episodes.csv"), "--out",
                            str(tmp_path / "empty"), "--log-level", "WARNING"]) == 0
    assert not any((tmp_path / "empty").iterdir())
    for argv in (["--replay-with", "sofar-7"], ["--replay", "x.csv", "--replay-with", "no-such-preset"]):
        with pytest.raises(SystemExit) as exc:
            stalls_cli.main(argv)
        assert exc.value.code == 2


def test_replay_records_the_steps_of_every_mpc_of_the_stack(tmp_path):
    """``"sofar-3"`` solves slow steps with its second MPC (the slow end rows): the recorder sees those steps too,
    so its stall is classified from records. Held-out dense interactive episode (base seed 9600): Laguna Seca,
    rho 0.1, gamma 0.5, stalled at 78.3 s turned about 0.46 rad beyond its turn-back room under a follow
    decision (``edge_no_turn_back``)."""
    row = {"track": "LagunaSeca", "rho": 0.1, "seed": 3422659077, "strategy": "gamma=0.5", "success": 0,
           "use_miqp": 1, "stalled": 1, "duration": 80.0, "n_opponents": 8, "stack": "sofar-3",
           "scenario": "interactive"}
    out, (first,) = _replay_rows(tmp_path, row)
    if first["outcome"] != "stalled":  # a seeded run reproduces on one instruction set only
        return
    assert first["cls"] == "edge_no_turn_back"
    with gzip.open(out / stalls_cli.RECORDS, "rt", newline="") as f:
        (steps,) = sr.records_from_rows(csv.DictReader(f)).values()
    assert len(steps) >= 150 and all(r.mpc_status for r in steps)


def _episodes(path: Path) -> dict[tuple, dict[str, str]]:
    with open(path, newline="") as f:
        return {(r["track"], float(r["rho"]), int(r["seed"]), float(r["strategy"][6:])): r
                for r in csv.DictReader(f) if r["strategy"].startswith("gamma=")}


@pytest.mark.parametrize("path", sorted((ROOT / "results").glob("**/stalls.csv")),
                         ids=lambda p: str(p.parent.relative_to(ROOT / "results")))
def test_committed_stall_rows_carry_the_hash_of_the_episode_they_replay(path: Path) -> None:
    """Each row of a committed stalls.csv names its episode: a row of a committed per-episode CSV (label
    ``committed <folder>``) or of the folder's own seed set (``fresh seed N``); it carries that row's hash, or,
    replayed with another controller (``--replay-with``), the hash of that controller in the episode's world."""
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    assert rows and list(rows[0]) == list(sr.REPORT_COLUMNS)
    sources: dict[Path, dict] = {}
    for r in rows:
        label = r["label"]
        src = (ROOT / label.removeprefix("committed ") if label.startswith("committed ") else path.parent)
        src = src / "table1_episodes.csv"
        if src not in sources:
            sources[src] = _episodes(src)
        key = (r["track"], float(r["rho"]), int(r["seed"]), float(r["gamma"]))
        episode = sources[src].get(key)
        assert episode is not None and r["config_hash"], (label, key)
        if r["stack"] == episode["stack"]:
            assert r["config_hash"] == episode["config_hash"], (label, key)
        else:
            assert r["config_hash"] == episode_config_hash(r["stack"], episode["scenario"], float(episode["duration"]))
