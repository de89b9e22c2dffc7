"""The one executor (sofar_agents.executor), table-driven: on every backend a rerun skips the tasks done, a task that
raises is counted and retried by the rerun, a worker that dies is counted as missing and its task retried, rows of
another configuration hash are not reused; killing or interrupting the driver leaves no worker behind."""

from __future__ import annotations

import importlib.util
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from sofar_agents.executor import execute, incomplete_message, missing_summary

from .executor_jobs import ToyJob, ToyTask, toy_hash
from .process_tree import alive, descendants, kill_all, wait_for

TESTS = Path(__file__).resolve().parents[1]
HASH_A, HASH_B = toy_hash({"stack": "sofar"}), toy_hash({"stack": "paper"})


def _tasks(tmp_path, actions, config_hash=HASH_A):
    return [ToyTask(f"t{k}", k, config_hash, action, str(tmp_path / f"marker{k}")) for k, action in enumerate(actions)]


# name: (actions of the first run, its (completed, failed, missing), the rerun's (skipped, completed, failed,
#        missing), backends that can run it)
CASES = {
    "a rerun skips the tasks done": (["ok", "ok", "ok"], (3, 0, 0), (3, 0, 0, 0), ("inline", "processes", "ray")),
    "a task that raises is counted and retried": (["ok", "raise_once", "ok"], (2, 1, 0), (2, 1, 0, 0),
                                                  ("inline", "processes", "ray")),
    "a worker that dies is counted as missing": (["ok", "die_once", "ok"], (2, 0, 1), (2, 1, 0, 0), ("processes",)),
    "every worker dies": (["die", "die", "die"], (0, 0, 3), (0, 0, 0, 3), ("processes",)),
}


@pytest.fixture(scope="module")
def ray_instance():
    ray = pytest.importorskip("ray")
    path = os.pathsep.join([str(TESTS), os.environ.get("PYTHONPATH", "")])  # the actors import the toy job
    ray.init(num_cpus=2, include_dashboard=False, logging_level="WARNING",
             runtime_env={"env_vars": {"PYTHONPATH": path}})
    yield
    ray.shutdown()


@pytest.mark.parametrize("backend", ["inline", "processes", "ray"])
@pytest.mark.parametrize("case", sorted(CASES))
def test_resume_and_faults(case, backend, tmp_path, request, caplog):
    actions, first, rerun, backends = CASES[case]
    if backend not in backends:
        pytest.skip(f"{backend} cannot run this case")
    if backend == "ray":
        request.getfixturevalue("ray_instance")
    tasks = _tasks(tmp_path, actions)
    job = ToyJob(tmp_path / "rows.csv")
    stats = execute(tasks, job, workers=2, backend=backend, progress=False)
    assert (stats.requested, stats.skipped, stats.completed, stats.failed, stats.missing) == (3, 0, *first)
    assert sorted(r["name"] for r in job.rows()) == sorted(  # only finished tasks are written, once each
        t.name for t, a in zip(tasks, actions) if a == "ok")
    if stats.failed:
        assert len(stats.errors) == stats.failed and "ValueError: boom t1" in stats.errors[0]
        assert "boom t1" in caplog.text
    assert bool(incomplete_message(stats, "out", "toys")) == bool(stats.unfinished)
    again = execute(tasks, ToyJob(tmp_path / "rows.csv"), workers=2, backend=backend, progress=False)
    assert (again.skipped, again.completed, again.failed, again.missing) == rerun
    names = [r["name"] for r in job.rows()]
    assert len(names) == len(set(names))  # never a task twice


@pytest.mark.parametrize("backend", ["inline", "processes"])
def test_rows_of_another_configuration_hash_are_not_reused(backend, tmp_path):
    job = ToyJob(tmp_path / "rows.csv")
    assert execute(_tasks(tmp_path, ["ok", "ok"]), job, workers=2, backend=backend, progress=False).completed == 2
    changed = execute(_tasks(tmp_path, ["ok", "ok"], HASH_B), job, workers=2, backend=backend, progress=False)
    assert (changed.skipped, changed.completed) == (0, 2)
    assert sorted((r["name"], r["config_hash"]) for r in job.rows()) == [
        ("t0", HASH_A), ("t0", HASH_B), ("t1", HASH_A), ("t1", HASH_B)]


@pytest.mark.parametrize("kwargs, message", [
    ({"workers": 0}, "workers must be >= 1"),
    ({"backend": "threads"}, "unknown backend"),
    ({"address": "auto"}, "needs backend='ray'"),
])
def test_bad_arguments_are_refused_before_anything_runs(tmp_path, kwargs, message):
    with pytest.raises(ValueError, match=message):
        execute(_tasks(tmp_path, ["ok"]), ToyJob(tmp_path / "rows.csv"), progress=False, **kwargs)
    assert not (tmp_path / "rows.csv").exists()


def test_the_incomplete_message_names_the_unit_and_the_causes(tmp_path):
    stats = execute(_tasks(tmp_path, ["ok", "die", "raise_once"]), ToyJob(tmp_path / "rows.csv"), workers=2,
                    backend="processes", progress=False)
    assert missing_summary(stats, "toys") == ("2 of 3 toys are missing (1 failed, 1 lost with a worker process "
                                              "that died)")


# name: (signal to the driver, the driver's arguments: backend and transport only)
LIFETIME = {
    "executor, driver killed": (signal.SIGKILL, ("processes", False)),
    "executor, Ctrl-C": (signal.SIGINT, ("processes", False)),
    "transport (training pool), driver killed": (signal.SIGKILL, ("processes", True)),
}


@pytest.mark.parametrize("case", sorted(LIFETIME))
def test_the_workers_end_with_their_driver(case, tmp_path):
    sig, (backend, transport_only) = LIFETIME[case]
    # a driver started from a shell gets Ctrl-C as KeyboardInterrupt; one started from a process that ignores SIGINT
    # (as a test process can, after some library set it) would inherit the ignored disposition and never see it
    code = (f"import signal, sys; signal.signal(signal.SIGINT, signal.default_int_handler); "
            f"sys.path.insert(0, {str(TESTS)!r}); from eval.executor_jobs import drive; "
            f"drive({str(tmp_path / 'rows.csv')!r}, 4, {backend!r}, {transport_only!r})")
    driver = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                              start_new_session=True)
    tracked: dict = {}
    try:
        def workers_up() -> bool:
            tracked.update(descendants(driver.pid))
            return sum("spawn_main" in cmd for cmd in tracked.values()) >= 2 or driver.poll() is not None

        assert wait_for(workers_up, 60), "no workers after 60 s"
        assert driver.poll() is None, driver.stderr.read().decode()[-3000:]
        wait_for(lambda: False, 2.0)  # into their sleeping tasks
        driver.send_signal(sig)
        rc = driver.wait(20)
        assert rc != 0
        if sig == signal.SIGINT:
            assert b"KeyboardInterrupt" in driver.stderr.read()
        assert wait_for(lambda: not any(alive(p) for p in tracked), 15.0), [
            cmd[:80] for p, cmd in tracked.items() if alive(p)]
    finally:
        if driver.poll() is None:
            driver.kill()
            driver.wait(10)
        kill_all(tracked)


def _load(script: str):
    path = TESTS.parent / "eval" / script
    spec = importlib.util.spec_from_file_location(f"executor_cli_{path.stem}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _interventions_csv(tmp_path) -> Path:
    from .episode_csv import write_episode_csv

    path = tmp_path / "set" / "table1_episodes.csv"
    rows = [{"track": "Kentucky", "rho": 0.1, "seed": 3895481847, "strategy": "gamma=0.05", "success": False,
             "use_miqp": miqp, "stack": "paper", "duration": 6.0} for miqp in (True, False)]
    write_episode_csv(path, rows)
    return path


def _table1_rows(out):
    from sofar_agents import evaluation as ev

    return [r["track"] for r in ev.read_episode_csv(out / "table1_episodes.csv")]


def _race_rows(out):
    from sofar_agents.evaluation.multi_agent import read_race_csv

    return [r.track for r in read_race_csv(out / "multi_agent_races.csv")]


def _intervention_rows(out):
    import csv

    with open(out / "interventions.csv", newline="") as f:
        return [f"{r['use_miqp']}/{r['kind']}" for r in csv.DictReader(f)]


SMALL = ["--tracks", "LagunaSeca", "Monza", "--gammas", "0.5", "--no-adaptive", "--episodes", "1", "--workers", "1",
         "--no-progress"]
# name: (script, its arguments (tmp_path -> argv), the runner to break (module, class), the unit, the rows written)
TABLES = {
    "Table I": ("table.py", lambda tmp: [*SMALL, "--rhos", "0.5", "--duration", "0.3"],
                ("sofar_agents.evaluation.sweep", "_EpisodeRunner"), "episodes", _table1_rows),
    "multi-agent table": ("table.py", lambda tmp: [*SMALL, "--multi-agent", "--cars", "2", "--duration", "1"],
                          ("sofar_agents.evaluation.multi_agent", "RaceRunner"), "races", _race_rows),
    "interventions": ("interventions.py", lambda tmp: [str(_interventions_csv(tmp)), "--quick", "--windows", "1",
                                                       "--placebo-lead", "1"],
                      ("sofar_agents.evaluation.interventions", "InterventionRunner"), "failed episodes",
                      _intervention_rows),
}


@pytest.mark.parametrize("table", sorted(TABLES))
def test_each_table_runs_on_the_executor_fails_with_status_1_and_resumes(table, tmp_path, monkeypatch, caplog):
    """Table I, the multi-agent table and the interventions: a task that raises makes the script exit with status 1
    and say so; the rerun runs that task only and completes the results."""
    import importlib

    script, argv, (module_name, runner_name), unit, rows_of = TABLES[table]
    out = tmp_path / "out"
    args = [*argv(tmp_path), "--out", str(out)]
    module = importlib.import_module(module_name)
    runner = getattr(module, runner_name)

    class FailsItsFirstTask(runner):
        def run(self, task):
            if not getattr(self, "failed_once", False):
                self.failed_once = True
                raise RuntimeError("injected failure")
            return super().run(task)

    monkeypatch.setattr(module, runner_name, FailsItsFirstTask)
    assert _load(script).main(args) == 1
    assert "injected failure" in caplog.text
    assert f"incomplete: 1 of 2 {unit} are missing (1 failed); re-run with the same --out {out}" in caplog.text
    first = rows_of(out)
    monkeypatch.setattr(module, runner_name, runner)
    caplog.clear()
    assert _load(script).main(args) == 0
    assert "incomplete" not in caplog.text
    final = rows_of(out)
    assert len(final) > len(first) and len(set(final)) == len(final)  # the missing task ran, nothing twice


def test_interventions_resume_by_episode_and_configuration_hash(tmp_path):
    """The replays' CSV is the results file: an episode whose rows it holds under the same configuration hash is
    skipped; rows of another hash, or of the layout before the column, are not reused, and once the run is complete
    the file holds exactly its rows in task order."""
    from sofar_agents.evaluation import EpisodeTask, Strategy
    from sofar_agents.evaluation import interventions as iv

    task = EpisodeTask(track="Kentucky", strategy=Strategy.fixed(0.05), rho=0.1, episode=4, seed=3895481847,
                       duration=6.0, stack="paper")
    ivs = [iv.Intervention(0.6, 1.0, hold_s=1.0)]
    path = tmp_path / "interventions.csv"
    results, stats = iv.replay_interventions([task], ivs, path)
    assert stats.completed == 1 and [r.intervention for r in results] == [None, ivs[0]]
    assert {r.config_hash for r in results} == {task.config_hash}
    text = path.read_text()
    results_again, again = iv.replay_interventions([task], ivs, path)
    assert (again.skipped, again.completed) == (1, 0) and path.read_text() == text and results_again == results
    lines = text.splitlines()
    for stale in (text.replace(task.config_hash, "0123456789ab"),  # another configuration
                  "\n".join(line.rsplit(",", 1)[0] for line in lines) + "\n"):  # written before the column
        path.write_text(stale)
        rerun = iv.replay_interventions([task], ivs, path)[1]
        assert (rerun.skipped, rerun.completed) == (0, 1) and path.read_text() == text
    more = iv.replay_interventions([task], [*ivs, iv.Intervention(0.3, 1.0, hold_s=1.0)], path)[1]
    assert more.completed == 1  # another intervention asked for: the episode is replayed
