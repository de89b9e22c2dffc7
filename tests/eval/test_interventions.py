"""Counterfactual gamma switches before a failure: windows, schedules and counts by hand, one real replay."""

from __future__ import annotations

import csv
import math
import sys
from pathlib import Path

import pytest

from sofar_agents.evaluation import EpisodeTask, Strategy
from sofar_agents.evaluation import interventions as iv

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "eval"))
import interventions as interventions_cli

from .episode_csv import write_episode_csv

# A paper-stack episode that fails after 32 steps at gamma 0.05 (Kentucky, rho 0.1: the ego closes on a
# slow car at about 50 m/s). It is short enough to reproduce on every instruction set; a 10 s horizon keeps
# a rescued replay at 100 steps.
SHORT_FAILURE = EpisodeTask(track="Kentucky", strategy=Strategy.fixed(0.05), rho=0.1, episode=4, seed=3895481847,
                            duration=10.0, stack="paper")


def test_control_step_is_the_race_step():
    from sofar_env.race import RaceConfig

    assert iv._CONTROL_DT == RaceConfig().dt


def test_window_in_steps_by_hand():
    assert iv.Intervention(0.6, 4.0, hold_s=2.0).steps(100) == (60, 120)
    assert iv.Intervention(0.6, 1.0, hold_s=0.0).steps(100) == (90, 100)
    # displaced 5 s earlier: the same length, 50 steps before
    assert iv.Intervention(0.6, 4.0, hold_s=2.0, lead_s=5.0, kind="displaced").steps(100) == (10, 70)
    # clipped at the start; a window that would lie wholly before it is empty
    assert iv.Intervention(0.6, 4.0).steps(30) == (0, 50)
    first, end = iv.Intervention(0.6, 4.0, lead_s=20.0, kind="displaced").steps(30)
    assert end <= first


def test_schedule_switches_inside_the_window_only():
    s = iv._Schedule(0.05, 0.6, first=2, end=4)
    assert [s(None)[0] for _ in range(6)] == [0.05, 0.05, 0.6, 0.6, 0.05, 0.05]
    base = iv._Schedule(0.3)
    assert [base(None)[0] for _ in range(3)] == [0.3, 0.3, 0.3]


def test_default_interventions_are_every_switch_then_two_placebos():
    ivs = iv.default_interventions(0.05, gammas=(0.15, 0.6), windows_s=(1.0, 4.0), hold_s=2.0,
                                   placebo_delta=0.01, placebo_lead_s=20.0)
    assert [(i.gamma, i.window_s, i.kind) for i in ivs[:4]] == [(0.15, 1.0, "switch"), (0.6, 1.0, "switch"),
                                                                 (0.15, 4.0, "switch"), (0.6, 4.0, "switch")]
    tiny, displaced = ivs[4], ivs[5]
    assert (tiny.kind, tiny.gamma, tiny.window_s, tiny.lead_s) == ("tiny", 0.06, 4.0, 0.0)
    # the displaced placebo is the switch farthest from the base gamma, at the longest window
    assert (displaced.kind, displaced.gamma, displaced.window_s, displaced.lead_s) == ("displaced", 0.6, 4.0, 20.0)
    assert iv.default_interventions(1.0, gammas=(0.3,), windows_s=(2.0,))[1].gamma == 1.0  # capped at the bound


@pytest.mark.parametrize("kwargs, message", [
    ({"gamma": 0.01, "window_s": 1.0}, "gamma must lie in"),
    ({"gamma": 1.5, "window_s": 1.0}, "gamma must lie in"),
    ({"gamma": math.nan, "window_s": 1.0}, "gamma must lie in"),
    ({"gamma": 0.5, "window_s": -1.0}, "window_s must be a finite number"),
    ({"gamma": 0.5, "window_s": math.inf}, "window_s must be a finite number"),
    ({"gamma": 0.5, "window_s": 1.0, "hold_s": -0.5}, "hold_s must be a finite number"),
    ({"gamma": 0.5, "window_s": 1.0, "lead_s": math.nan}, "lead_s must be a finite number"),
    ({"gamma": 0.5, "window_s": 0.0, "hold_s": 0.0}, "window_s \\+ hold_s > 0"),
    ({"gamma": 0.5, "window_s": 1.0, "kind": "other"}, "kind must be"),
])
def test_bad_interventions_are_named(kwargs, message):
    with pytest.raises(ValueError, match=message):
        iv.Intervention(**kwargs)


def test_bad_calls_are_named():
    with pytest.raises(ValueError, match="at least one"):
        iv.default_interventions(0.05, gammas=())
    policy_task = EpisodeTask(track="Kentucky", strategy=Strategy(name="adaptive", kind="policy", path="p.json"),
                              rho=0.1, episode=0, seed=1)
    with pytest.raises(ValueError, match="fixed-gamma episode, got strategy 'adaptive'"):
        iv.intervene(policy_task, [])
    with pytest.raises(ValueError, match="workers"):
        iv.run_interventions([SHORT_FAILURE], [], workers=0)


def test_failed_episodes_picks_the_failures_of_one_gamma():
    common = {"use_miqp": True, "duration": 200.0, "stack": "paper", "scenario": "paper", "n_opponents": "",
              "episode": 2}
    rows = [
        {**common, "strategy": "gamma=0.05", "success": False, "track": "Monza", "rho": 0.1, "seed": 7},
        {**common, "strategy": "gamma=0.05", "success": True, "track": "Monza", "rho": 0.3, "seed": 8},
        {**common, "strategy": "gamma=0.50", "success": False, "track": "Monza", "rho": 0.1, "seed": 7},
        {**common, "strategy": "gamma=0.05", "success": False, "track": "Kentucky", "rho": 0.65, "seed": 9,
         "use_miqp": False, "duration": 100.0, "stack": "sofar", "scenario": "interactive", "n_opponents": 8},
    ]
    found = iv.failed_episodes(rows, 0.05)
    fixed = Strategy.fixed(0.05)
    assert found == [EpisodeTask("Monza", fixed, 0.1, 2, 7, True, 200.0, None, "paper", "paper"),
                     EpisodeTask("Kentucky", fixed, 0.65, 2, 9, False, 100.0, 8, "sofar", "interactive")]
    assert iv.failed_episodes(rows, 0.05, limit=1) == found[:1]
    assert iv.failed_episodes(rows, 0.95) == []


def _result(intervention, base_outcome, steps, outcome, base_steps=100):
    return iv.InterventionResult(SHORT_FAILURE, 0.05, intervention, base_steps, base_outcome, steps, outcome)


def test_rescued_delayed_and_the_summary_by_hand():
    sw = iv.Intervention(0.6, 4.0, hold_s=2.0)
    placebo = iv.Intervention(0.06, 4.0, hold_s=2.0, kind="tiny")
    results = [
        _result(None, "collision", 100, "collision"),
        _result(sw, "collision", 100, "success"),       # rescued
        _result(sw, "collision", 121, "off_track"),     # failed 2.1 s after the base failure: delayed
        _result(sw, "collision", 120, "collision"),     # within the hold: not delayed
        _result(placebo, "collision", 90, "collision"),
        _result(None, "success", 2000, "success"),      # did not fail again on this machine
    ]
    assert [r.rescued for r in results] == [False, True, False, False, False, False]
    assert [r.delayed for r in results] == [False, True, True, False, False, False]
    summary = iv.summarize_interventions(results)
    assert (summary["replayed"], summary["failed"], summary["not_reproduced"]) == (2, 1, 1)
    assert summary["failure_kinds"] == {"collision": 1}
    assert summary["interventions"][sw] == {"episodes": 3, "rescued": 1, "delayed": 2}
    assert summary["interventions"][placebo] == {"episodes": 1, "rescued": 0, "delayed": 0}
    text = iv.format_interventions(summary, 0.05)
    assert "| γ 0.60, 4 s before | switch | 3 | 1 | 33 | 2 |" in text
    assert "placebo: tiny change" in text
    rows = iv.intervention_rows(results)
    assert [r["kind"] for r in rows] == ["base", "switch", "switch", "switch", "tiny", "base"]
    assert set(rows[0]) == set(iv.INTERVENTION_COLUMNS)


def test_a_replay_reproduces_the_failure_and_a_switch_to_the_same_gamma_changes_nothing():
    """Closed loop: the base replay fails within the first seconds (the ego runs into a much slower car);
    an 'intervention' whose gamma equals the base gamma is the same episode, step for step."""
    same = iv.Intervention(0.05, 1.0, hold_s=1.0)
    base, replay = iv.intervene(SHORT_FAILURE, [same])
    assert base.intervention is None and base.base_outcome == "collision"
    assert 20 <= base.base_steps <= 60
    assert (replay.steps, replay.outcome) == (base.steps, base.outcome)
    assert not replay.rescued and not replay.delayed


def test_cli_quick_run_writes_csv_and_markdown(tmp_path, capsys):
    csv_path = tmp_path / "set" / "table1_episodes.csv"
    write_episode_csv(csv_path, [
        {"track": "Kentucky", "rho": 0.1, "seed": 3895481847, "strategy": "gamma=0.05", "success": False,
         "use_miqp": True, "stack": "paper", "duration": 6.0},
        {"track": "Kentucky", "rho": 0.1, "seed": 3895481847, "strategy": "gamma=0.50", "success": False,
         "use_miqp": True, "stack": "paper", "duration": 6.0},
    ])
    out = tmp_path / "out"
    code = interventions_cli.main([str(csv_path), "--quick", "--windows", "1", "--placebo-lead", "1",
                                   "--out", str(out)])
    assert code == 0
    lines = (out / "interventions.csv").read_text().splitlines()
    assert lines[0].split(",") == list(iv.INTERVENTION_COLUMNS)
    kinds = [line.split(",")[9] for line in lines[1:]]
    assert kinds == ["base", "switch", "tiny", "displaced"]
    md = (out / "interventions.md").read_text()
    assert "1 failed episodes replayed, 1 failed again" in md and "placebo: displaced" in md
    assert "--limit 2" in capsys.readouterr().out


@pytest.mark.parametrize("extra, message", [
    (["--gamma", "0.5"], "no failed episode of gamma 0.50"),
    (["--limit", "0"], "argument --limit: must be a whole number >= 1"),  # usage errors of the argument types
    (["--gammas", "2.0"], "argument --gammas: must lie in"),
])
def test_cli_bad_input(tmp_path, capsys, extra, message):
    csv_path = tmp_path / "set" / "table1_episodes.csv"
    write_episode_csv(csv_path, [{"track": "Monza", "rho": 0.1, "seed": 1, "strategy": "gamma=0.05",
                                  "success": False, "use_miqp": True}])
    try:
        code = interventions_cli.main([str(csv_path), "--out", str(tmp_path / "o"), *extra])
    except SystemExit as exc:
        code = exc.code
    assert code == 2
    assert message in capsys.readouterr().err


def _task(seed):
    return EpisodeTask(track="Monza", strategy=Strategy.fixed(0.05), rho=0.3, episode=0, seed=seed, stack="paper")


def test_placebo_comparison_pairs_the_switch_with_the_displaced_placebo_by_hand():
    sw = iv.Intervention(0.6, 4.0)
    short = iv.Intervention(0.6, 1.0)  # another window: not compared
    placebo = iv.Intervention(0.6, 4.0, lead_s=20.0, kind="displaced")
    outcome = {True: "success", False: "collision"}
    results = []
    # failures 1-4: the switch rescues 1 and 2, the placebo 2 and 3; failure 5 is too early for the placebo
    for seed, (by_switch, by_placebo) in enumerate([(True, False), (True, True), (False, True), (False, False)], 1):
        results += [iv.InterventionResult(_task(seed), 0.05, None, 500, "collision", 500, "collision"),
                    iv.InterventionResult(_task(seed), 0.05, sw, 500, "collision", 2000, outcome[by_switch]),
                    iv.InterventionResult(_task(seed), 0.05, short, 500, "collision", 500, "collision"),
                    iv.InterventionResult(_task(seed), 0.05, placebo, 500, "collision", 2000, outcome[by_placebo])]
    results += [iv.InterventionResult(_task(5), 0.05, None, 100, "collision", 100, "collision"),
                iv.InterventionResult(_task(5), 0.05, sw, 100, "collision", 2000, "success")]
    (c,) = iv.placebo_comparisons(results)
    assert (c.a, c.b) == (sw.label, placebo.label)
    assert (c.n, c.a_only, c.b_only, c.unpaired) == (4, 1, 1, 1)
    assert c.p_value == 1.0
    text = iv.format_interventions(iv.summarize_interventions(results), 0.05, [c])
    assert "against the displaced placebo" in text and f"| {sw.label} | {placebo.label} | 4 |" in text


def test_rows_round_trip_through_results_from_rows():
    results = [iv.InterventionResult(SHORT_FAILURE, 0.05, None, 32, "collision", 32, "collision"),
               iv.InterventionResult(SHORT_FAILURE, 0.05, iv.Intervention(0.3, 2.0, 1.0), 32, "collision", 100,
                                     "success"),
               iv.InterventionResult(SHORT_FAILURE, 0.05, iv.Intervention(0.6, 4.0, 2.0, 20.0, "displaced"), 32,
                                     "collision", 40, "off_track")]
    rows = iv.intervention_rows(results)
    as_text = [{k: str(v) for k, v in r.items()} for r in rows]  # as csv.DictReader gives them
    back = iv.results_from_rows(as_text)
    assert iv.intervention_rows(back) == rows
    assert [r.rescued for r in back] == [False, True, False]
    with pytest.raises(ValueError, match="row 1 is not an interventions.csv row"):
        iv.results_from_rows([{**as_text[0], "kind": "switch", "gamma": "2.0", "window_s": "1", "hold_s": "1",
                               "lead_s": "0"}])


def test_cli_report_remakes_the_markdown_without_running(tmp_path, capsys):
    results = [iv.InterventionResult(_task(1), 0.05, None, 500, "collision", 500, "collision"),
               iv.InterventionResult(_task(1), 0.05, iv.Intervention(0.6, 4.0), 500, "collision", 2000, "success"),
               iv.InterventionResult(_task(1), 0.05, iv.Intervention(0.6, 4.0, lead_s=20.0, kind="displaced"), 500,
                                     "collision", 700, "collision")]
    path = tmp_path / "interventions.csv"
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=iv.INTERVENTION_COLUMNS)
        w.writeheader()
        w.writerows(iv.intervention_rows(results))
    (tmp_path / "interventions.md").write_text("old table\n\n3 replays, 2,700 env steps, 1 s on 1 worker(s).\n")
    assert interventions_cli.main([str(path), "--report"]) == 0
    md = (tmp_path / "interventions.md").read_text()
    assert "| γ 0.60, 4 s before | switch | 1 | 1 | 100 | 1 |" in md
    assert "against the displaced placebo" in md
    assert md.rstrip().endswith("3 replays, 2,700 env steps, 1 s on 1 worker(s).")  # the run's own line is kept
    capsys.readouterr()
    bad = tmp_path / "bad.csv"
    bad.write_text("track,rho\nMonza,0.1\n")
    assert interventions_cli.main([str(bad), "--report"]) == 2
    assert "is not an interventions.csv (missing columns" in capsys.readouterr().err
    assert interventions_cli.main([str(path), str(path), "--report"]) == 2
    assert "takes one interventions.csv" in capsys.readouterr().err
