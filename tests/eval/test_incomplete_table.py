"""A table left incomplete is an error: when a worker process dies mid-sweep, eval/table.py writes what finished,
says how many episodes (races) are missing and that the same --out resumes, and exits with status 1; the rerun
completes the table (Table I and the multi-agent table alike: both run on the one executor)."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from sofar_agents import evaluation as ev
from sofar_agents.evaluation.multi_agent import read_race_csv

from .process_tree import descendants, kill_all, wait_for

ROOT = Path(__file__).resolve().parents[2]
TABLE = ROOT / "eval" / "table.py"
COMMON = ["--tracks", "LagunaSeca", "Monza", "--gammas", "0.5", "--no-adaptive", "--episodes", "1", "--duration", "5",
          "--workers", "2", "--no-progress"]

CASES = {  # name: (table.py options, the unit, the results CSV and how to read the circuits of its rows)
    "process-pool": (["--rhos", "0.5"], "episodes",
                     ("table1_episodes.csv", lambda p: [r["track"] for r in ev.read_episode_csv(p)])),
    "multi-agent-pool": (["--multi-agent"], "races",
                         ("multi_agent_races.csv", lambda p: [r.track for r in read_race_csv(p)])),
}
"""Both run on the executor: the same worker processes, the same message, the same resume."""


@pytest.mark.parametrize("case", sorted(CASES))
def test_a_dead_worker_makes_the_table_fail_and_the_rerun_resumes(case, tmp_path):
    options, unit, (csv_name, tracks_of) = CASES[case]
    message = (rf"incomplete: 1 of 2 {unit} are missing \(1 lost with a worker process that died\); re-run "
               r"with the same --out \S+ to resume")
    argv = [sys.executable, str(TABLE), *COMMON, *options, "--out", str(tmp_path)]
    driver = subprocess.Popen(argv, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    seen: dict = {}
    try:
        def a_worker() -> int | None:
            kids = descendants(driver.pid)
            seen.update(kids)
            return next((pid for (pid, _), cmd in kids.items() if "spawn_main" in cmd), None)

        assert wait_for(lambda: a_worker() is not None or driver.poll() is not None, 120)
        victim = a_worker()
        assert victim is not None, driver.communicate(timeout=60)[1][-3000:]
        os.kill(victim, signal.SIGKILL)  # dies with the task it was given (one each: two tasks, two workers)
        out, err = driver.communicate(timeout=300)
    finally:
        if driver.poll() is None:
            driver.kill()
        kill_all(seen)
    assert driver.returncode == 1, err[-3000:]
    assert re.search(message, err), err[-3000:]
    assert "Traceback" not in err
    assert "Incomplete" in out  # the Markdown says it too
    again = subprocess.run(argv, cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert again.returncode == 0, again.stderr[-3000:]
    assert "incomplete" not in again.stderr
    assert sorted(tracks_of(tmp_path / csv_name)) == ["LagunaSeca", "Monza"]


def test_incomplete_message_counts_the_missing_episodes():
    assert ev.incomplete_message(ev.SweepStats(requested=4, completed=4), "out") is None
    text = ev.incomplete_message(ev.SweepStats(requested=5, completed=2, failed=1, missing=2), "results/x")
    assert text == ("incomplete: 3 of 5 episodes are missing (1 failed, 2 lost with a worker process that died); "
                    "re-run with the same --out results/x to resume (the finished episodes are kept, only the missing "
                    "ones run)")
