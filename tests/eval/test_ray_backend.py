"""The executor's Ray backend (sofar_agents.executor.ray_actors): a sweep on Ray writes the same rows as the process pool, survives a
dead worker, and without Ray says how to install it."""

from __future__ import annotations

import builtins
import importlib.util
import os
from pathlib import Path

import pytest

from sofar_agents import evaluation as ev
from sofar_agents.evaluation import sweep
from sofar_agents.evaluation.sweep import _EpisodeRunner

ray = pytest.importorskip("ray")
TABLE = Path(__file__).resolve().parents[2] / "eval" / "table.py"


def _tasks():
    return ev.table1_tasks([ev.Strategy.fixed(0.5)], ["LagunaSeca", "Monza"], [0.5], episodes=1, duration=0.5)


def _rows(path):
    return sorted((tuple((k, v) for k, v in sorted(r.items()) if k != "wall_time") for r in ev.read_episode_csv(path)))


@pytest.fixture(scope="module")
def local_ray():
    ray.init(num_cpus=2, include_dashboard=False, logging_level="WARNING")
    yield
    ray.shutdown()


def test_ray_sweep_matches_local_pool(tmp_path, local_ray):
    tasks = _tasks()
    local = ev.run_sweep(tasks, tmp_path / "local.csv", workers=1, progress=False)
    on_ray = ev.run_sweep(tasks, tmp_path / "ray.csv", workers=2, progress=False, backend="ray")
    assert (on_ray.completed, on_ray.failed, on_ray.workers) == (2, 0, 2) and local.completed == 2
    assert _rows(tmp_path / "ray.csv") == _rows(tmp_path / "local.csv")
    again = ev.run_sweep(tasks, tmp_path / "ray.csv", workers=2, progress=False, backend="ray")
    assert (again.skipped, again.completed) == (2, 0)


def test_ray_sweep_retries_a_task_whose_worker_died(tmp_path, local_ray, monkeypatch):
    marker = str(tmp_path / "killed")

    class KillingRunner(_EpisodeRunner):  # a local class: Ray ships it to the workers by value
        def run(self, task):
            if not os.path.exists(marker):
                open(marker, "w").close()
                os._exit(1)  # the worker process dies mid-sweep, once
            return super().run(task)

    monkeypatch.setattr(sweep, "_EpisodeRunner", KillingRunner)
    tasks = _tasks()
    stats = ev.run_sweep(tasks, tmp_path / "ray.csv", workers=2, progress=False, backend="ray")
    assert os.path.exists(marker)
    assert (stats.completed, stats.failed) == (2, 0)
    rows = ev.read_episode_csv(tmp_path / "ray.csv")
    assert sorted(r["track"] for r in rows) == ["LagunaSeca", "Monza"]  # complete, no duplicate


def test_ray_backend_without_ray_says_how_to_install(tmp_path, monkeypatch, capsys):
    real_import = builtins.__import__

    def no_ray(name, *args, **kwargs):
        if name == "ray" or name.startswith("ray."):
            raise ImportError("No module named 'ray'")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_ray)
    with pytest.raises(ImportError, match=r'pip install "sofar\[ray\]"'):
        ev.run_sweep(_tasks(), tmp_path / "x.csv", progress=False, backend="ray")
    assert not (tmp_path / "x.csv").exists()

    spec = importlib.util.spec_from_file_location("table_script", TABLE)
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    assert script.main(["--quick", "--no-adaptive", "--backend", "ray", "--out", str(tmp_path / "t"),
                        "--no-progress"]) == 2
    assert 'pip install "sofar[ray]"' in capsys.readouterr().err
