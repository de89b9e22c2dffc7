"""The off-track diagnosis: the classification rules on synthetic step records, one real replay of a spin."""

from __future__ import annotations

import csv
import dataclasses
import gzip
import math
import sys
from pathlib import Path

import pytest

from sofar_agents.evaluation import off_tracks as ot
from sofar_agents.evaluation.protocol import EpisodeTask, Strategy

from .episode_csv import write_episode_csv

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "eval"))
import off_tracks as off_tracks_cli  # noqa: E402

# A step on a left turn, the car on its line and its plan inside: nothing wrong.
_ON = ot.OffTrackRecord(t=0.0, s=0.0, n=0.0, e=0.0, v=30.0, kappa=0.005, width_left=6.0, width_right=6.0, beta=0.01,
                        yaw_rate=0.15, accel=0.0, lat_slack=0.0, mpc_status="solved", plan_n_end=0.0, plan_room=3.0,
                        nearest=80.0, following=False)


def _window(n: int = 40, **changes) -> list[ot.OffTrackRecord]:
    return [dataclasses.replace(_ON, t=0.1 * k, **changes) for k in range(n)]


@pytest.mark.parametrize(("changes", "expected"), [
    ({"beta": -0.3}, "spin"),
    ({"plan_room": -0.2}, "planned"),
    ({}, "left_plan"),
    ({"plan_room": math.nan, "mpc_status": "fallback_brake"}, "left_plan"),  # no plan: not the plan's departure
])
def test_each_rule_by_hand(changes, expected):
    assert ot.classify(_window(**changes))[0] == expected


def test_rules_apply_in_order_and_over_their_windows():
    # a spin whose plan also left is a spin (rule 1 first)
    assert ot.classify(_window(beta=0.4, plan_room=-1.0))[0] == "spin"
    # slip counts over the last 2 s only, the plan's room over the last 1 s by majority
    early = _window()
    early[5] = dataclasses.replace(early[5], beta=0.5)
    assert ot.classify(early)[0] == "left_plan"
    late = _window()
    late[-3] = dataclasses.replace(late[-3], beta=-0.2)
    assert ot.classify(late)[0] == "spin"
    few = _window()
    few[-1] = dataclasses.replace(few[-1], plan_room=-0.1)
    assert ot.classify(few)[0] == "left_plan"
    most = [dataclasses.replace(r, plan_room=-0.1) if r.t > 3.05 else r for r in _window()]
    assert ot.classify(most)[0] == "planned"


def test_evidence():
    recs = _window()
    recs = [dataclasses.replace(r, plan_n_end=-2.0 + 0.1 * k, accel=-6.0 if k >= 30 else 0.0)
            for k, r in enumerate(recs)]
    recs[-1] = dataclasses.replace(recs[-1], n=-5.5, v=20.0)  # at the right edge of a left turn: the outside
    _, ev = ot.classify(recs)
    assert ev["side"] == "right" and ev["outside"] is True
    assert ev["v"] == 20.0 and ev["lat_demand"] == pytest.approx(2.0)
    assert ev["accel"] == pytest.approx(-6.0)
    assert ev["plan_move"] == pytest.approx(1.9)  # 20 records of 0.1 m in the last 2 s
    left = dataclasses.replace(recs[-1], n=5.5)
    assert ot.classify(recs[:-1] + [left])[1]["outside"] is False


# The dynamic world's earliest departure of the committed runs: Monza, rho 0.1, from 46 m/s behind a field at a tenth
# of the pace, the plan moves the car 11 m across the track into the first chicane, and it spins off at 7.4 s.
_SPIN = {"track": "Monza", "strategy": "gamma=0.30", "rho": 0.1, "seed": 3046734017, "success": 0, "use_miqp": 1,
         "off_track": 1, "sim_time": 7.4, "stack": "sofar-6", "scenario": "dynamic"}


def test_a_spin_of_the_dynamic_world_replayed():
    task = EpisodeTask(track="Monza", strategy=Strategy.fixed(0.3), rho=0.1, episode=0, seed=3046734017,
                       use_miqp=True, duration=200.0, stack="sofar-6", scenario="dynamic")
    rep = ot.record_off_track(task)
    assert rep.result.off_track and 7.0 < rep.result.sim_time < 8.0
    assert rep.cls == "spin" and rep.evidence["slip"] > 0.5 and rep.evidence["plan_move"] > 5.0
    assert len(rep.records) == 40 and rep.records[-1].t == pytest.approx(rep.result.sim_time)


def test_the_script_replays_writes_and_resumes(tmp_path, capsys):
    csv_path = tmp_path / "table1_episodes.csv"
    write_episode_csv(csv_path, [_SPIN, {**_SPIN, "off_track": 0, "success": 1, "sim_time": 200.0, "seed": 1}])
    out = tmp_path / "out"
    assert off_tracks_cli.main(["--replay", str(csv_path), "--out", str(out), "--log-level", "WARNING"]) == 0
    with open(out / "off_tracks.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 1 and rows[0]["cls"] == "spin" and rows[0]["outcome"] == "off_track"
    with gzip.open(out / "records.csv.gz", "rt", newline="") as f:
        assert len(list(csv.DictReader(f))) == 40
    assert "| `sofar-6` | 1 | 1 | 1 | 0 | 0 |" in (out / "off_tracks.md").read_text()
    # a rerun finds the episode done and runs nothing
    assert off_tracks_cli.main(["--replay", str(csv_path), "--out", str(out), "--log-level", "WARNING"]) == 0
    assert "this call ran for 0 s" in capsys.readouterr().out
    with open(out / "off_tracks.csv", newline="") as f:
        assert len(list(csv.DictReader(f))) == 1
