"""Episode records and their CSV files: columns, typed reading, flushed appending, resume keys.

A sweep appends one row of :data:`EPISODE_COLUMNS` per finished episode (and, when
traced, rows of :data:`TRACE_COLUMNS` per control step). Files of an older format
(without the ``stack``, ``n_opponents``, ``scenario``, ``stalled`` or ``config_hash`` columns) are read as
they are and migrated in place on the next append; their rows stand for the ``sofar``
controller, the default opponent count and the paper's world, and carry no configuration hash
(``""``): their resume keys match no task of this version (whose keys hold the hash), so a rerun
runs those episodes again under the current configuration instead of reusing them.

``stalled`` of an older row is *unknown* (an empty field, read as None), not 0: those
episodes ran without the stall rule, so none was ended by it, but whether the ego stood
still for ``stall_seconds`` was not recorded (an episode that did is in the file as a
success reaching the duration). Only a rerun tells; the tables show such groups as
unknown. Their ``success`` is that of the rules they ran under (collision, leaving the
track).
A row counts only once its line is complete: the writer ends every row with a newline
(flushed together with it), so a last line without one was torn by a run killed
mid-write (a duration ``60`` cut to ``6``, a policy id cut short) and is ignored by
:func:`read_episode_csv` and dropped when the file is next appended to or migrated;
the episode is then run again. Files of every format end their rows this way.
A row's resume key (:func:`_row_key`) equals :attr:`EpisodeTask.key` of the task that
produced it, so a rerun skips the episodes already in the file.
"""

from __future__ import annotations

import csv
import io
import logging
import os
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from sofar_agents.evaluation.files import write_text_atomic
from sofar_agents.evaluation.protocol import DEFAULT_DURATION, LEGACY_STACK, EpisodeTask, _key, exact_text

logger = logging.getLogger(__name__)

EPISODE_COLUMNS: tuple[str, ...] = (
    "track", "strategy", "rho", "seed", "success", "sim_time", "laps", "overtakes", "collision", "off_track",
    "slack_steps", "steps", "mean_gamma", "mpc_failures", "miqp_failures", "wall_time",
    "episode", "use_miqp", "duration", "policy_id", "stack", "config_hash", "n_opponents", "scenario", "stalled",
)
"""Columns of the per-episode CSV (one row per episode)."""
TRACE_COLUMNS: tuple[str, ...] = (
    "track", "strategy", "rho", "seed", "step", "sim_time", "gamma", "nearest_opponent_m", "min_barrier",
)
"""Columns of the per-step trace CSV."""


@dataclass
class EpisodeResult:
    """What one episode produced (one CSV row)."""

    track: str
    strategy: str
    rho: float
    seed: int
    success: bool
    sim_time: float
    laps: float
    overtakes: int
    collision: bool
    off_track: bool
    slack_steps: int
    steps: int
    mean_gamma: float
    mpc_failures: int
    miqp_failures: int
    wall_time: float
    episode: int = 0
    use_miqp: bool = True
    duration: float = DEFAULT_DURATION
    policy_id: str = ""
    stack: str = "sofar"
    scenario: str = "paper"
    n_opponents: int | str = ""
    """Opponent count of the episode ("" for the environment's default)."""
    stalled: bool | None = False
    """The stall rule ended the episode (the ego stood still too long); None: unknown (older rows)."""
    config_hash: str = ""
    """:func:`sofar_env.config_hash.config_hash` of the environment's configuration ("": rows written before
    the column)."""

    def to_row(self) -> dict[str, Any]:
        row = asdict(self)
        return {k: row[k] for k in EPISODE_COLUMNS}


def _as_bool(x: Any) -> bool:
    if isinstance(x, str):
        return x.strip().lower() in ("1", "true", "yes", "1.0")
    return bool(x)


_INT_COLUMNS = {"seed", "overtakes", "slack_steps", "steps", "mpc_failures", "miqp_failures", "episode"}
_BOOL_COLUMNS = {"success", "collision", "off_track", "use_miqp"}
_FLOAT_COLUMNS = {"rho", "sim_time", "laps", "mean_gamma", "wall_time", "duration"}
_UNKNOWN_BOOL_COLUMNS = {"stalled"}
"""Boolean columns whose empty value means unknown (None)."""


def _parse_row(row: Mapping[str, Any]) -> dict[str, Any]:
    out = dict(row)
    for k, v in row.items():
        if k in _UNKNOWN_BOOL_COLUMNS:
            out[k] = None if v is None or (isinstance(v, str) and not v.strip()) else _as_bool(v)
        elif k in _BOOL_COLUMNS:
            out[k] = _as_bool(v)
        elif k in _INT_COLUMNS:
            out[k] = int(float(v))
        elif k in _FLOAT_COLUMNS:
            out[k] = float(v)
    return out


_EXACT_COLUMNS = {"rho", "duration"}
"""Float columns of the resume key: written so that they read back to the same float (:func:`exact_text`)."""


def _csv_value(v: Any, exact: bool = False) -> Any:
    if isinstance(v, bool):
        return int(v)
    if isinstance(v, float):
        if exact:
            return exact_text(v)
        return f"{v:.6g}" if abs(v) < 1e5 else f"{v:.1f}"
    return v


def _complete_lines(path: Path) -> str:
    """The text of ``path`` up to its last newline: a last line without one was torn mid-write."""
    with open(path, newline="") as f:
        text = f.read()
    end = max(text.rfind("\n"), text.rfind("\r")) + 1
    if end < len(text):
        logger.warning("%s: ignoring a torn last line (no newline): %r", path, text[end:])
    return text[:end]


def read_csv_rows(path: str | os.PathLike, columns: Sequence[str], *, added: Mapping[str, str] | None = None,
                  may_be_empty: Iterable[str] = (), kind: str = "SOfAR episode CSV") -> list[dict[str, str]]:
    """The complete rows of a CSV written with ``columns``, as strings; the one reader of the result CSVs.

    ``added``: columns that files of an older format lack, with the value their rows stand for. A header
    without one of the other ``columns`` raises ``ValueError`` naming the file (``kind``: what it should
    be). Incomplete rows are dropped: a last line without its newline (a run killed mid-write, logged), and
    rows anywhere in the file with a missing value, an empty value in a column not in ``may_be_empty`` or
    more values than the header. A missing or empty file has no rows.
    """
    p = Path(path)
    if not p.exists() or p.stat().st_size == 0:
        return []
    added = dict(added or {})
    may_be_empty = set(may_be_empty)
    rows = []
    with io.StringIO(_complete_lines(p), newline="") as f:
        reader = csv.DictReader(f)
        header = reader.fieldnames or []
        missing = [c for c in columns if c not in header and c not in added]
        if missing:
            raise ValueError(f"{p} is not a {kind} (missing columns {missing}); use another --out")
        present = [c for c in columns if c in header]
        for row in reader:
            if None in row or any(row.get(c) is None or (row[c] == "" and c not in may_be_empty)
                                  for c in present):
                logger.warning("skipping an incomplete row of %s: %s", p, row)
                continue
            for c, default in added.items():  # rows of an older format
                row.setdefault(c, default)
            rows.append(row)
    return rows


def read_episode_csv(path: str | os.PathLike) -> list[dict[str, Any]]:
    """The rows of a per-episode CSV, typed (:func:`read_csv_rows`: incomplete rows dropped, a file of
    another kind raises ``ValueError`` naming it; a row whose values do not parse is skipped with a warning)."""
    rows = []
    for row in read_csv_rows(path, EPISODE_COLUMNS, added=_ADDED_COLUMNS, may_be_empty=_MAY_BE_EMPTY):
        try:
            rows.append(_parse_row(row))
        except ValueError:
            logger.warning("skipping an unreadable row of %s: %s", path, row)
    return rows


def read_seed_sets(paths: Sequence[str | os.PathLike]) -> dict[str, list[dict[str, Any]]]:
    """Per-episode CSVs, one per seed set, by name: the CSV's folder for a ``*_episodes.csv``, else its path.

    Raises ``ValueError`` naming the file if one does not exist or is given twice.
    """
    sets: dict[str, list[dict[str, Any]]] = {}
    for path in paths:
        p = Path(path)
        if not p.is_file():
            raise ValueError(f"no such CSV: {p}")
        name = str(p.parent) if p.name.endswith("_episodes.csv") else str(p)
        if name in sets:
            raise ValueError(f"{p} is given twice")
        sets[name] = read_episode_csv(p)
    return sets


def pool_seed_sets(sets: Mapping[str, Sequence[Mapping[str, Any]]]) -> list[dict[str, Any]]:
    """The rows of several seed sets (:func:`read_seed_sets`) as one list, in order.

    Raises ``ValueError`` when an episode (strategy, circuit, rho, seed) is in two of them: pooling is for
    different seed sets of one experiment, whose episodes pair within each set.
    """
    rows: list[dict[str, Any]] = []
    where: dict[tuple, str] = {}
    for name, set_rows in sets.items():
        for r in set_rows:
            key = (r["strategy"], r["track"], float(r["rho"]), int(r["seed"]))
            if key in where:
                raise ValueError(f"episode {key} is in two of the files ({where[key]}, {name}): "
                                 "pool different seed sets only")
            where[key] = name
            rows.append(dict(r))
    return rows


def write_markdown(path: str | os.PathLike, text: str) -> Path:
    """Write a Markdown report to ``path`` atomically, creating its folder; returns the path."""
    return write_text_atomic(path, text)


_ADDED_COLUMNS = {"stack": LEGACY_STACK, "n_opponents": "", "scenario": "paper", "stalled": "", "config_hash": ""}
"""Columns added after the first format, with the value that rows of older files stand for ("" of
``stalled``: unknown, see the module docstring)."""
_MAY_BE_EMPTY = {"policy_id", "n_opponents", "stalled", "config_hash"}


def _is_older_header(header: Sequence[str], columns: Sequence[str]) -> bool:
    return list(header) == [c for c in columns if c not in _ADDED_COLUMNS or c in header]


def _migrate_csv(path: Path, header: Sequence[str], columns: Sequence[str]) -> None:
    """Rewrite an episode CSV of an older format with the current columns (atomically)."""
    with io.StringIO(_complete_lines(path), newline="") as f:
        rows = [r for r in csv.DictReader(f)]
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(columns))
        w.writeheader()
        for r in rows:
            if None in r or any(v is None for v in r.values()):
                continue  # a torn last line
            w.writerow({c: r.get(c, _ADDED_COLUMNS.get(c, "")) for c in columns})
    os.replace(tmp, path)
    logger.info("%s: added the columns %s (older format)", path, [c for c in columns if c not in header])


def _drop_torn_line(path: Path) -> None:
    """Cut a last line without its newline (a run killed mid-write) off ``path``, in place."""
    with open(path, "rb+") as f:
        data = f.read()
        end = max(data.rfind(b"\n"), data.rfind(b"\r")) + 1
        if end < len(data):
            logger.warning("%s: dropping a torn last line (no newline): %r", path, data[end:])
            f.truncate(end)


class _AppendingCSV:
    """A CSV opened for appending: header when new, one flushed row per write."""

    def __init__(self, path: str | os.PathLike, columns: Sequence[str]) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        new = not self.path.exists() or self.path.stat().st_size == 0
        if not new:
            with open(self.path, newline="") as f:
                header = next(csv.reader(f), [])
            if list(header) != list(columns) and _is_older_header(header, columns):
                _migrate_csv(self.path, header, columns)
            elif list(header) != list(columns):
                raise ValueError(f"{self.path} has columns {header}, expected {list(columns)}; use another --out")
            else:
                _drop_torn_line(self.path)
        self._f = open(self.path, "a", newline="")
        self._w = csv.writer(self._f)
        self.columns = tuple(columns)
        if new:
            self._w.writerow(self.columns)
            self._f.flush()

    def write(self, row: Mapping[str, Any] | Sequence[Any]) -> None:
        values = [row[c] for c in self.columns] if isinstance(row, Mapping) else list(row)
        exact = [c in _EXACT_COLUMNS for c in self.columns]
        self._w.writerow([_csv_value(v, i < len(exact) and exact[i]) for i, v in enumerate(values)])
        self._f.flush()

    def write_many(self, rows: Iterable[Sequence[Any]]) -> None:
        self._w.writerows([[_csv_value(v) for v in r] for r in rows])
        self._f.flush()

    def close(self) -> None:
        self._f.close()


def _row_key(row: Mapping[str, Any]) -> tuple:
    return _key(row["track"], row["strategy"], row.get("policy_id", ""), row["rho"], row["seed"],
                _as_bool(row.get("use_miqp", True)), row.get("duration", DEFAULT_DURATION),
                row.get("stack") or LEGACY_STACK, row.get("n_opponents"), row.get("scenario") or "paper",
                row.get("config_hash") or "")


def select_rows(rows: Iterable[Mapping[str, Any]], tasks: Sequence[EpisodeTask]) -> list[dict[str, Any]]:
    """The rows of ``rows`` that belong to ``tasks`` (a CSV may hold episodes of other runs).

    The resume key holds the configuration hash, so rows of another configuration (or without a hash) are
    never selected for a task; tasks whose rows would put two hashes under one strategy name raise
    ``ValueError`` naming both (:func:`~sofar_agents.evaluation.configs.check_one_config`).
    """
    from sofar_agents.evaluation.configs import check_one_config

    wanted = {t.key for t in tasks}
    out, seen = [], set()
    for r in rows:
        k = _row_key(r)
        if k in wanted and k not in seen:
            out.append(_parse_row(r))
            seen.add(k)
    check_one_config(out, _config_label, "select_rows")
    return out


def _config_label(row: Mapping[str, Any]) -> str:
    """The strategy label under which rows must share one configuration hash: strategy, controller preset,
    world and duration (rows that differ in these are told apart by their own columns)."""
    return (f"{row.get('stack') or 'sofar'}:{row['strategy']} ({row.get('scenario') or 'paper'}, "
            f"{exact_text(float(row.get('duration', DEFAULT_DURATION)))} s)")


def rows_of_other_configs(rows: Iterable[Mapping[str, Any]], tasks: Sequence[EpisodeTask]) -> dict[str, int]:
    """``{hash: count}`` of the rows that would be rows of ``tasks`` but for their configuration hash (``""``:
    rows written before the hash): episodes of another configuration, which the tables leave out and name."""
    wanted = {t.key[:-1]: t.key[-1] for t in tasks}
    out: dict[str, int] = {}
    for r in rows:
        k = _row_key(r)
        if k[:-1] in wanted and wanted[k[:-1]] != k[-1]:
            out[k[-1]] = out.get(k[-1], 0) + 1
    return out


def read_trace_csv(path: str | os.PathLike, strategy: str | None = None) -> dict[str, np.ndarray]:
    """gamma and nearest-opponent distance from a trace CSV (optionally one strategy only).

    A torn last line (no newline) is ignored, as in :func:`read_episode_csv`.
    """
    gam, dist, barrier = [], [], []
    with io.StringIO(_complete_lines(Path(path)), newline="") as f:
        for row in csv.DictReader(f):
            if strategy is not None and row.get("strategy") != strategy:
                continue
            try:
                gam.append(float(row["gamma"]))
                dist.append(float(row["nearest_opponent_m"]))
                barrier.append(float(row.get("min_barrier", "nan") or "nan"))
            except (KeyError, ValueError):
                continue
    return {"gamma": np.asarray(gam), "nearest_opponent_m": np.asarray(dist), "min_barrier": np.asarray(barrier)}
