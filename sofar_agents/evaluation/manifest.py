"""Experiments as manifests: ``experiments/NAME.toml`` says what a results folder holds and how to make it.

The keys of a manifest and how it is read: :mod:`~sofar_agents.evaluation.manifest_spec` (:class:`Manifest`,
:func:`load_manifest`, re-exported here); the kinds ``pareto`` and ``interventions``:
:mod:`~sofar_agents.evaluation.manifest_replays`.

:func:`run_manifest` runs a manifest into its folder (resuming, as the table scripts do) and writes
``<name>.manifest.json`` there (:func:`record_path`; one per manifest, so that two manifests of one folder keep
theirs): the manifest, its configuration hash, the code commit, the machine, its CPU flags and the wall time;
``earlier_runs`` lists the commit, wall time and end of the runs of the same hash that a resumed run continued
(and ``adopted_from``, the manifest whose rows :mod:`~.manifest_adopt` copied in).
:func:`check_manifest` compares the hash a manifest resolves to with the hashes the rows of its committed CSV
carry. :func:`rerun_rows` re-makes chosen committed rows in another folder and
compares them field by field (every column of the committed file but ``wall_time`` and ``config_hash``; for
the multi-agent table the races, re-run one by one; for interventions every replay of the episodes named, with
all the manifest's interventions), which is what justifies
giving rows written before the hash column the manifest's hash (:func:`backfill_hash`), or rows of a hash
that moved without changing the episodes the new one (:func:`restamp_hash`).
"""

from __future__ import annotations

import csv
import dataclasses
import json
import logging
import os
import platform
import subprocess
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from sofar_agents.evaluation import manifest_replays as replays
from sofar_agents.evaluation.configs import row_hash, write_config_json
from sofar_agents.evaluation.files import write_json_atomic, write_text_atomic
from sofar_agents.evaluation.manifest_spec import KINDS, Manifest, load_manifest, manifest_paths
from sofar_agents.evaluation.results import EPISODE_COLUMNS, LEGACY_STACK, read_csv_rows

__all__ = ["KINDS", "Manifest", "load_manifest", "manifest_paths", "run_manifest", "record_path", "check_manifest",
           "ManifestCheck", "episode_ids", "row_id", "row_episode", "row_length", "raw_rows", "rerun_rows", "backfill_hash",
           "restamp_hash"]

logger = logging.getLogger(__name__)

_NOT_COMPARED = ("wall_time", "config_hash")
"""Columns that :func:`rerun_rows` does not compare (the wall time varies; old rows have no hash)."""
_NOT_RECORDED = {"miqp_failures": "-1"}
"""Committed values that stand for "not recorded": a row written before its file had the column, kept with this
value when a resumed run added the column (a race's MIQP failures); :func:`rerun_rows` does not compare them."""


def row_id(m: Manifest, row: dict[str, str]) -> tuple:
    """What names a row in a CSV of ``m``'s kind: the episode ``(track, strategy, rho, seed, use_miqp)``, for
    the multi-agent table the race ``(track, strategy, seed)``, for interventions the replay
    (:func:`~sofar_agents.evaluation.manifest_replays.replay_row_id`)."""
    if m.kind == "multi-agent":
        return row["track"], row["strategy"], row["seed"]
    if m.kind == "interventions":
        return replays.replay_row_id(row)
    if m.kind == "standing-start":
        from sofar_agents.evaluation.standing_start import probe_row_id

        return probe_row_id(row)
    return row["track"], row["strategy"], row["rho"], row["seed"], row["use_miqp"]


def row_episode(m: Manifest, row: dict[str, str]) -> tuple:
    """The episode (race) a row belongs to, as :func:`episode_ids` names them: :func:`row_id`, but for
    interventions the replayed episode (:func:`~sofar_agents.evaluation.manifest_replays.replay_episode`)."""
    return replays.replay_episode(row) if m.kind == "interventions" else row_id(m, row)


def row_length(m: Manifest, row: dict[str, str]) -> float:
    """How long a committed row's episode ran (steps; for a race the car-seconds driven over the possible; for a
    replay its steps; for a standing start the distance it gained, so that the placements it stood at come
    first): :func:`rerun_rows` re-makes the shortest ones."""
    key = {"multi-agent": "driven", "standing-start": "distance"}.get(m.kind, "steps")
    return float(row[key])


def _race_tasks(m: Manifest, root: str | os.PathLike) -> list:
    from sofar_agents.evaluation.multi_agent import multi_agent_tasks

    return multi_agent_tasks(m.strategies(root), m.tracks, m.episode_count, m.seed, m.cars, m.duration, m.stack,
                             m.scenario, int(m.opponents or 0))


def episode_ids(m: Manifest, root: str | os.PathLike) -> set[tuple]:
    """:func:`row_episode` as written in a CSV, of every episode (race; replayed episode) of the table ``m`` (a
    CSV may hold rows of other runs too)."""
    from sofar_agents.evaluation.protocol import exact_text, miqp_ablation_tasks, table1_tasks

    if m.kind == "multi-agent":
        return {(t.track, t.strategy.name, str(t.seed)) for t in _race_tasks(m, root)}
    if m.kind == "interventions":
        return {replays.task_episode(t) for t in replays.failed_tasks(m, root)}
    if m.kind == "standing-start":
        return _probe_ids(m)
    if m.kind == "pareto":
        tasks = replays.pareto_tasks(m, root)
        return {(t.track, t.strategy.name, exact_text(t.rho), str(t.seed), str(int(t.use_miqp))) for t in tasks}
    strategies = m.strategies(root)
    if m.kind == "table2":
        tasks = miqp_ablation_tasks(strategies, m.episode_count, m.rhos, m.track, m.seed, m.duration, stack=m.stack,
                                    scenario=m.scenario)
    elif m.kind in ("table1", "figures", "floor"):
        tasks = table1_tasks(strategies, m.tracks, m.rhos, m.episode_count, m.seed, m.duration, stack=m.stack,
                             scenario=m.scenario, n_opponents=m.opponents)
    else:
        raise ValueError(f"unknown kind {m.kind!r}")
    return {(t.track, t.strategy.name, exact_text(t.rho), str(t.seed), str(int(t.use_miqp))) for t in tasks}


def _probe_ids(m: Manifest) -> set[tuple]:
    """The placements of a standing-start manifest, as its CSV names them."""
    from sofar_agents.evaluation.standing_start import placements, probe_row_id
    from sofar_env.tracks import Track

    vehicle = m.config().race.vehicle
    return {probe_row_id({"track": track, "s": p.s, "side": p.side, "clearance": p.clearance})
            for track in m.tracks for p in placements(Track.load(track), m.count, m.clearances, vehicle)}


def _git_commit(root: Path) -> str:
    """The commit checked out at ``root``, with ``-dirty`` when a tracked file outside ``results/`` has changes:
    the code that ran differed from the commit. Changed result files (rows a run resumes from, other tables made
    before it in the same checkout) do not make it dirty."""
    try:
        out = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True,
                             check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no", "--",
                                ".", ":(exclude)results"], capture_output=True, text=True, check=True).stdout.strip()
        return out + ("-dirty" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def _cpu() -> dict[str, Any]:
    """Model name and flags of the first CPU in ``/proc/cpuinfo`` (empty where there is none)."""
    info: dict[str, Any] = {"count": os.cpu_count()}
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        return info
    for line in text.splitlines():
        key, _, value = line.partition(":")
        key = key.strip()
        if key == "model name" and "model" not in info:
            info["model"] = value.strip()
        elif key in ("flags", "Features") and "flags" not in info:
            info["flags"] = value.split()
    return info


def record_path(m: Manifest, folder: str | os.PathLike) -> Path:
    """The run record of ``m`` in ``folder``: ``<name>.manifest.json``."""
    return Path(folder) / f"{m.name}.manifest.json"


def run_manifest(m: Manifest, root: str | os.PathLike, *, workers: int | None = None,
                 out: str | os.PathLike | None = None, progress: bool = True, tasks_filter=None) -> Any:
    """Run ``m`` into ``root/m.out`` (or ``out``), resuming from its CSV, and write :func:`record_path` and the
    resolved configuration (``config.json``) there.

    Returns the table's report (``markdown``). ``tasks_filter`` (for :func:`rerun_rows`) limits the episodes
    run (for pareto and interventions: runs only their rows, no report, and returns None).
    """
    root = Path(root)
    folder = Path(out) if out is not None else root / m.out
    folder.mkdir(parents=True, exist_ok=True)
    strategies = m.strategies(root)
    write_config_json(folder, [m.config()])
    commit, t0 = _git_commit(root), time.perf_counter()
    if m.kind == "interventions":
        report = replays.run_interventions_manifest(m, root, folder, workers, progress, keep=tasks_filter)
    elif m.kind == "figures":
        report = replays.run_figures_manifest(m, root, folder, workers, progress, keep=tasks_filter)
    elif m.kind == "standing-start":
        from sofar_agents.evaluation.standing_start import run_probe_manifest

        report = run_probe_manifest(m, folder, keep=tasks_filter)
    elif m.kind == "pareto" and tasks_filter is not None:
        report = replays.run_pareto_rows(m, root, folder, tasks_filter, workers)
    elif m.kind == "pareto":
        report = replays.run_pareto_manifest(m, root, folder, workers, progress)
    elif m.kind == "floor":
        from sofar_agents.evaluation.gamma_floor import run_floor_study
        from sofar_agents.evaluation.pareto import preference_family

        report = run_floor_study(m.policy_path(root), preference_family(m.safety_weights)[0], m.floors(), folder,
                                 gammas=m.floor_gammas, tracks=m.tracks, rhos=m.rhos,
                                 episodes=m.episode_count, base_seed=m.seed, duration=m.duration, workers=workers,
                                 progress=progress, stack=m.stack, scenario=m.scenario, n_opponents=m.opponents,
                                 trace=m.trace, tasks_filter=tasks_filter)
    elif m.kind == "multi-agent":
        from sofar_agents.evaluation.multi_agent import run_multi_agent_table

        report = run_multi_agent_table(strategies, folder, tracks=m.tracks, races=m.episode_count,
                                       base_seed=m.seed, cars=m.cars, duration=m.duration, stack=m.stack,
                                       scenario=m.scenario, workers=workers, progress=progress,
                                       opponents=int(m.opponents or 0), prefix=m.prefix or "multi_agent")
    elif m.kind == "table2":
        from sofar_agents.evaluation.experiments import run_miqp_ablation

        report = run_miqp_ablation(strategies, folder, episodes=m.episode_count, rhos=m.rhos, track=m.track,
                                   base_seed=m.seed, duration=m.duration, workers=workers, progress=progress,
                                   prefix=m.prefix or "table2", stack=m.stack, scenario=m.scenario,
                                   tasks_filter=tasks_filter)
    else:
        from sofar_agents.evaluation.experiments import run_table1

        report = run_table1(strategies, folder, tracks=m.tracks, rhos=m.rhos, episodes=m.episode_count,
                            base_seed=m.seed, duration=m.duration, workers=workers, progress=progress,
                            prefix=m.prefix or "table1", stack=m.stack, scenario=m.scenario,
                            n_opponents=m.opponents, tasks_filter=tasks_filter)
    record = {"manifest": m.name, "settings": {k: v for k, v in dataclasses.asdict(m).items() if k != "name"},
              "config_hash": [m.config_hash], "commit": commit,
              "machine": {"node": platform.node(), "platform": platform.platform(), "python": sys.version.split()[0],
                          "cpu": _cpu()},
              "wall_time_s": round(time.perf_counter() - t0, 3), "finished_at": time.strftime("%Y-%m-%dT%H:%M:%S%z")}
    record["earlier_runs"] = _earlier_runs(record_path(m, folder), m.config_hash)
    write_json_atomic(record_path(m, folder), record, indent=1, sort_keys=True)
    return report


def _earlier_runs(path: Path, config_hash: str) -> list[dict[str, Any]]:
    """The runs a resumed table was made by before this one: those of the record at ``path`` (its own run and its
    ``earlier_runs``) when it is of the same configuration hash; [] for a fresh folder or another hash."""
    try:
        old = json.loads(path.read_text())
    except (OSError, ValueError):
        return []
    if not isinstance(old, dict) or old.get("config_hash") != [config_hash]:
        return []
    runs = [r for r in old.get("earlier_runs", []) if isinstance(r, dict)]
    last = {k: old.get(k) for k in ("commit", "wall_time_s", "finished_at")}
    if "adopted_from" in old:  # rows another manifest ran (:mod:`.manifest_adopt`)
        last["adopted_from"] = old["adopted_from"]
    return runs + [last]


@dataclass
class ManifestCheck:
    """What :func:`check_manifest` found."""

    name: str
    config_hash: str
    csv_path: Path
    rows: int = 0
    hashes: dict[str, int] = field(default_factory=dict)
    """Rows per hash the CSV carries (``""``: rows without one)."""

    @property
    def status(self) -> str:
        """``"ok"`` (every row carries the manifest's hash), ``"unhashed"`` (rows without a hash, none with
        another), ``"missing"`` (no rows) or ``"mismatch"`` (rows with another hash)."""
        if not self.rows:
            return "missing"
        if any(h and h != self.config_hash for h in self.hashes):
            return "mismatch"
        return "unhashed" if "" in self.hashes else "ok"

    def line(self) -> str:
        counts = ", ".join(f"{n} rows {h or 'without a hash'}" for h, n in sorted(self.hashes.items()))
        return f"{self.name}: {self.status} (manifest {self.config_hash}; {self.csv_path}: {counts or 'no rows'})"


def check_manifest(m: Manifest, root: str | os.PathLike) -> ManifestCheck:
    """Resolve ``m``'s hash and count the hashes the rows of its CSV (``root/m.out``) carry."""
    path = Path(root) / m.out / m.csv_name
    check = ManifestCheck(m.name, m.config_hash, path)
    if path.is_file():
        with open(path, newline="") as f:
            for row in csv.DictReader(f):
                h = row_hash(row)
                check.hashes[h] = check.hashes.get(h, 0) + 1
                check.rows += 1
    return check


_OLDER_EPISODE_COLUMNS = {"stack": LEGACY_STACK, "n_opponents": "", "scenario": "paper", "stalled": "",
                          "config_hash": ""}
"""Episode columns that CSVs of older formats lack, with the value their rows stand for (as the table reader has
them; "" of ``stalled``: unknown)."""
_OLDER_RACE_COLUMNS = {"opponents": "0", "config_hash": "", "miqp_failures": "-1"}


def raw_rows(path: str | os.PathLike, kind: str = "table1") -> list[dict[str, str]]:
    """The complete rows of an episode CSV (``kind`` ``"multi-agent"``: a race CSV; ``"interventions"``: an
    ``interventions.csv``; ``"standing-start"``: a probe's CSV) as written (strings); the columns of an older
    format that the file lacks hold the value its rows stand for (``config_hash`` "")."""
    if kind == "interventions":
        from sofar_agents.evaluation.interventions import _read_rows

        return _read_rows(Path(path))
    if kind == "multi-agent":
        from sofar_agents.evaluation.multi_agent import RACE_COLUMNS

        return read_csv_rows(path, RACE_COLUMNS, added=_OLDER_RACE_COLUMNS, may_be_empty=("policy_id", "config_hash"),
                             kind="per-race CSV")
    if kind == "standing-start":
        from sofar_agents.evaluation.standing_start import ROW_COLUMNS

        return read_csv_rows(path, ROW_COLUMNS, kind="standing-start CSV")
    return read_csv_rows(path, EPISODE_COLUMNS, added=_OLDER_EPISODE_COLUMNS,
                         may_be_empty=("policy_id", "n_opponents", "stalled", "config_hash"))


def _header(path: Path) -> list[str]:
    with open(path, newline="") as f:
        return next(csv.reader(f), [])


def _rerun_races(m: Manifest, root: str | os.PathLike, wanted: set[tuple], out: Path) -> None:
    """Run the races of ``m`` named in ``wanted`` one by one into ``out``'s race CSV (as the table writes it)."""
    from sofar_agents.evaluation.multi_agent import _append, run_race

    policies: dict[str, Any] = {}
    out.mkdir(parents=True, exist_ok=True)
    for task in _race_tasks(m, root):
        if (task.track, task.strategy.name, str(task.seed)) in wanted:
            if task.strategy.name not in policies:
                policies[task.strategy.name] = task.strategy.build()
            _append(out / m.csv_name, run_race(task, policies[task.strategy.name]))


def rerun_rows(m: Manifest, root: str | os.PathLike, rows: Sequence[dict[str, str]], out: str | os.PathLike,
               workers: int | None = 1, columns: Sequence[str] | None = None) -> list[str]:
    """Run the episodes (races; replayed episodes, with all their replays) of the committed ``rows`` (strings, as
    :func:`raw_rows` gives them) through ``m`` into ``out`` and compare ``columns`` (default: every column of
    ``m``'s committed CSV) but ``wall_time`` and ``config_hash`` as written. Returns the differences (empty: the
    rows are re-made bit for bit); a row whose episode ``m`` does not hold is a difference too."""
    wanted = {row_episode(m, r) for r in rows}
    if columns is None:
        committed = Path(root) / m.out / m.csv_name
        columns = _header(committed) if committed.is_file() else list(rows[0]) if rows else []
    if m.kind == "multi-agent":
        _rerun_races(m, root, wanted, Path(out))
    elif m.kind == "interventions":
        run_manifest(m, root, workers=workers, out=out, progress=False,
                     tasks_filter=lambda task: replays.task_episode(task) in wanted)
    elif m.kind == "standing-start":
        run_manifest(m, root, out=out, progress=False, tasks_filter=lambda ident: ident in wanted)
    else:
        def keep(task) -> bool:
            from sofar_agents.evaluation.protocol import exact_text

            return (task.track, task.strategy.name, exact_text(task.rho), str(task.seed),
                    str(int(task.use_miqp))) in wanted

        run_manifest(m, root, workers=workers, out=out, progress=False, tasks_filter=keep)
    made = {row_id(m, r): r for r in raw_rows(Path(out) / m.csv_name, m.kind)}
    diffs = []
    for r in rows:
        new = made.get(row_id(m, r))
        if new is None:
            diffs.append(f"{row_id(m, r)}: not re-made (not an episode of manifest {m.name})")
            continue
        for c in columns:
            unknown = _NOT_RECORDED.get(c) == r.get(c)
            if c not in _NOT_COMPARED and not unknown and r.get(c, "") != new.get(c, ""):
                diffs.append(f"{row_id(m, r)}: {c} {r.get(c)!r} committed, {new.get(c)!r} re-made")
        if new.get("config_hash") != m.config_hash:
            diffs.append(f"{row_id(m, r)}: re-made with config_hash {new.get('config_hash')}, "
                         f"manifest {m.config_hash}")
    return diffs


def restamp_hash(path: str | os.PathLike, old: str, new: str) -> int:
    """Replace the ``config_hash`` ``old`` by ``new`` in every row of the episode CSV ``path`` that has it,
    changing no other byte; atomic. For a configuration whose hash moved without changing the episodes (a
    field added with a default that keeps the behaviour), once :func:`rerun_rows` has shown that the rows are
    re-made under ``new``. Returns the number of rows changed."""
    p = Path(path)
    lines = p.read_bytes().decode("utf-8").splitlines(keepends=True)
    header = lines[0].rstrip("\r\n").split(",")
    if "config_hash" not in header:
        raise ValueError(f"{p}: no config_hash column")
    at, changed, out = header.index("config_hash"), 0, [lines[0]]
    for line in lines[1:]:
        body = line.rstrip("\r\n")
        fields = body.split(",")
        if len(fields) == len(header) and fields[at] == old:
            fields[at] = new
            changed += 1
        out.append(",".join(fields) + line[len(body):])
    write_text_atomic(p, "".join(out))
    return changed


def backfill_hash(path: str | os.PathLike, config_hash: str, last: bool = False) -> int:
    """Give every row of the episode CSV ``path`` (written before the ``config_hash`` column) the hash
    ``config_hash``: the column goes in after ``stack`` (``last``: at the end, where an ``interventions.csv`` has
    it), every other byte of the file stays as it is (values, line endings). The file is replaced atomically.
    Only for rows shown to be re-made by the configuration of that hash (:func:`rerun_rows`). Returns the number
    of rows; ``ValueError`` for a file that already has the column, lacks ``stack`` or holds quoted values."""
    p = Path(path)
    data = p.read_bytes().decode("utf-8")
    if '"' in data:
        raise ValueError(f"{p}: quoted values; not rewritten")
    lines = data.splitlines(keepends=True)
    header = lines[0].rstrip("\r\n").split(",")
    if "config_hash" in header or "stack" not in header:
        raise ValueError(f"{p}: has a config_hash column already or no stack column")
    at = len(header) if last else header.index("stack") + 1
    out = []
    for i, line in enumerate(lines):
        body = line.rstrip("\r\n")
        end = line[len(body):]
        fields = body.split(",")
        if len(fields) != len(header) or not end:
            raise ValueError(f"{p}: line {i + 1} is incomplete; not rewritten")
        fields.insert(at, "config_hash" if i == 0 else config_hash)
        out.append(",".join(fields) + end)
    write_text_atomic(p, "".join(out))
    return len(lines) - 1
