"""A toy job for the executor's tests: tasks that succeed, raise, kill their worker or sleep, rows in a small CSV
keyed by name and configuration hash. Importable by spawned workers (they get the test's ``sys.path``)."""

from __future__ import annotations

import csv
import hashlib
import json
import os
import time
from dataclasses import dataclass
from pathlib import Path

from sofar_agents.executor import Job, RunStats

COLUMNS = ("name", "value", "config_hash")


def toy_hash(config: dict) -> str:
    return hashlib.sha256(json.dumps(config, sort_keys=True).encode()).hexdigest()[:12]


@dataclass(frozen=True)
class ToyTask:
    """``action``: ``ok``, ``raise_once`` / ``die_once`` (the first run raises / kills its worker, leaving
    ``marker``), ``die`` (every run kills its worker) or ``sleep``. Not part of the key."""

    name: str
    value: int
    config_hash: str
    action: str = "ok"
    marker: str = ""

    @property
    def key(self) -> tuple:
        return (self.name, self.config_hash)


class ToyRunner:
    def run(self, task: ToyTask) -> dict:
        first = task.marker and not os.path.exists(task.marker)
        if first:
            Path(task.marker).touch()
        if task.action == "raise_once" and first:
            raise ValueError(f"boom {task.name}")
        if task.action == "die" or (task.action == "die_once" and first):
            os._exit(3)
        if task.action == "sleep":
            time.sleep(120)
        return {"name": task.name, "value": 2 * task.value, "config_hash": task.config_hash}

    def close(self) -> None:
        pass


class ToyJob(Job):
    unit = "toys"
    runner = ToyRunner

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self._f = None

    def rows(self) -> list[dict]:
        if not self.path.exists():
            return []
        with open(self.path, newline="") as f:
            return list(csv.DictReader(f))

    def done_keys(self) -> set:
        return {(r["name"], r["config_hash"]) for r in self.rows()}

    def open(self, pending) -> None:
        new = not self.path.exists()
        self._f = open(self.path, "a", newline="")
        self._w = csv.DictWriter(self._f, COLUMNS, lineterminator="\n")
        if new:
            self._w.writeheader()

    def write(self, task: ToyTask, payload: dict, stats: RunStats) -> None:
        self._w.writerow(payload)
        self._f.flush()

    def close(self) -> None:
        if self._f is not None:
            self._f.close()


def drive(path: str, n: int, backend: str, transport_only: bool = False) -> None:
    """A driver for the lifetime tests: ``n`` sleeping tasks on two workers (or two bare transport workers whose
    body sleeps in a call, as the training pool's do)."""
    if transport_only:
        from sofar_agents.worker_processes import WorkerProcess

        workers = [WorkerProcess(ToyRunner, name=f"toy-{k}") for k in range(2)]
        for w in workers:
            w.call("run", ToyTask(f"t{n}", 0, "", "sleep"))
        workers[0].answer()
        return
    from sofar_agents.executor import execute

    execute([ToyTask(f"t{k}", k, "", "sleep") for k in range(n)], ToyJob(Path(path)), workers=2, backend=backend,
            progress=False)
