"""The per-episode (Table I) and per-race (multi-agent) CSVs go through one reader: the same damage gives the same
outcome in both (incomplete rows dropped wherever they are, a foreign header a ValueError naming the file)."""

from __future__ import annotations

import csv
import io
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path

import pytest

from sofar_agents import evaluation as ev
from sofar_agents.evaluation import multi_agent as ma


def _episode_rows() -> tuple[list[str], list[dict]]:
    tasks = ev.table1_tasks([ev.Strategy.fixed(0.05)], ["Monza"], [0.3], 3, duration=20.0)
    rows = [ev.EpisodeResult(track=t.track, strategy=t.strategy.name, rho=t.rho, seed=t.seed, success=True,
                             sim_time=20.0, laps=0.5, overtakes=1, collision=False, off_track=False, slack_steps=0,
                             steps=200, mean_gamma=0.05, mpc_failures=0, miqp_failures=0, wall_time=1.0,
                             episode=t.episode, duration=t.duration, config_hash=t.config_hash).to_row()
            for t in tasks]
    return list(ev.EPISODE_COLUMNS), rows


def _race_rows() -> tuple[list[str], list[dict]]:
    tasks = ma.multi_agent_tasks([ev.Strategy.fixed(0.05)], ["Monza"], races=3, duration=20.0)
    rows = [asdict(ma.RaceResult(t.track, t.strategy.name, "", t.seed, t.cars, t.duration, t.stack, t.scenario,
                                 1, 0, 0, 0, 4, 1.0, 0.05, "0.9 0.95 1 0.98", 1.0)) for t in tasks]
    return list(ma.RACE_COLUMNS), rows


def _read_episodes(path: Path) -> list[int]:
    return [r["seed"] for r in ev.read_episode_csv(path)]


def _read_races(path: Path) -> list[int]:
    return [r.seed for r in ma.read_race_csv(path)]


KINDS = {"episodes": (_episode_rows, _read_episodes), "races": (_race_rows, _read_races)}


def _text(columns: list[str], rows: list[dict]) -> str:
    buf = io.StringIO()
    w = csv.DictWriter(buf, columns, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({c: int(v) if isinstance(v, bool) else v for c, v in r.items()})
    return buf.getvalue()


def _lines(text: str) -> list[str]:
    return text.splitlines(keepends=True)


def _cut_middle(text: str) -> str:
    lines = _lines(text)
    lines[2] = ",".join(lines[2].split(",")[:5]) + "\n"  # the second row stops after five values
    return "".join(lines)


def _empty_middle(text: str) -> str:
    lines = _lines(text)
    values = lines[2].split(",")
    values[4] = ""  # an empty count or flag
    lines[2] = ",".join(values)
    return "".join(lines)


def _long_middle(text: str) -> str:
    lines = _lines(text)
    lines[2] = lines[2].rstrip("\n") + "," + lines[3]  # a torn row continued by the next one
    del lines[3]
    return "".join(lines)


def _torn_last(text: str) -> str:
    return text[: text.rstrip("\n").rfind(",")]  # no newline at the end


def _foreign(text: str) -> str:
    return "name,layers,score\nmy-model,3,0.5\n"


def _garbled_middle(text: str) -> str:
    lines = _lines(text)
    values = lines[2].split(",")
    values[3] = "not-a-number"  # the seed
    lines[2] = ",".join(values)
    return "".join(lines)


# (id, damage, index of the rows read back, or the words of the error)
CASES: list[tuple[str, Callable[[str], str], list[int] | list[str]]] = [
    ("intact", lambda t: t, [0, 1, 2]),
    ("incomplete-middle-row", _cut_middle, [0, 2]),
    ("empty-value-in-a-middle-row", _empty_middle, [0, 2]),
    ("two-rows-on-one-line", _long_middle, [0]),
    ("torn-last-line", _torn_last, [0, 1]),
    ("unparsable-middle-row", _garbled_middle, [0, 2]),
    ("foreign-header", _foreign, ["missing columns", "use another --out"]),
]


@pytest.mark.parametrize("kind", sorted(KINDS))
@pytest.mark.parametrize(("case", "damage", "expected"), CASES, ids=[c[0] for c in CASES])
def test_both_readers_treat_damage_alike(tmp_path: Path, kind: str, case: str, damage: Callable[[str], str],
                                         expected: list) -> None:
    make, read = KINDS[kind]
    columns, rows = make()
    path = tmp_path / f"{case}.csv"
    path.write_text(damage(_text(columns, rows)))
    if expected and isinstance(expected[0], str):
        with pytest.raises(ValueError) as err:
            read(path)
        assert str(path) in str(err.value)
        for word in expected:
            assert word in str(err.value)
    else:
        assert read(path) == [int(rows[i]["seed"]) for i in expected]


def test_a_race_csv_from_before_the_opponents_column_reads_with_none(tmp_path: Path) -> None:
    columns, rows = _race_rows()
    path = tmp_path / "old.csv"
    path.write_text(_text([c for c in columns if c != "opponents"], [{k: v for k, v in r.items() if k != "opponents"}
                                                                      for r in rows]))
    assert [r.opponents for r in ma.read_race_csv(path)] == [0, 0, 0]
