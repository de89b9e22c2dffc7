"""The multi-agent table: races of the PettingZoo environment, every car driven by the same strategy.

A **race** is one seeded reset of :func:`sofar_env.multi_agent.parallel_env` with its defaults
(rolling start from the staggered grid, each car's speed factor drawn in ``race.pace_range``)
and ``cars`` controlled cars, run until every car is terminated (collision, leaving the track,
stalling; a terminated car leaves the race, the others race on) or the duration is reached. Race
``e`` of a circuit is reset with :func:`race_seed` ``(base_seed, track, e)``, which fixes the grid and
the pace: every strategy meets the same fields (paired races), and each circuit gets fields of its
own (the environment draws the pace from the reset seed alone, so plain seeds 0, 1, ... would repeat
the same fields on every circuit). A
strategy (:class:`~sofar_agents.evaluation.protocol.Strategy`: a fixed gamma, a PASTA checkpoint)
chooses every car's gamma from that car's own observation.

Per race the CSV row (:data:`RACE_COLUMNS`) holds the overtakes between controlled cars (the sum of
every car's ``info["overtakes"]``, which credits the passer only), the cars terminated by a
collision with another car, by leaving the track and by stalling, the cars that reached the
duration (success), and the car-seconds driven over ``cars x duration``. :func:`run_multi_agent_table`
runs (or resumes: the rows already in the CSV are skipped) a list of races and writes a Markdown
report on the executor (:mod:`sofar_agents.executor`: the resume, retry and fault behaviour of Table I);
:func:`format_multi_agent_table` summarises rows per strategy.
"""

from __future__ import annotations

import csv
import io
import logging
import os
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np

from sofar_agents.evaluation.files import write_text_atomic
from sofar_agents.evaluation.protocol import DEFAULT_DURATION, TRACKS, Strategy, _fmt_float, episode_seed, exact_text
from sofar_agents.evaluation.results import read_csv_rows
from sofar_agents.executor import Job, RunStats, execute

__all__ = ["RACE_COLUMNS", "race_seed", "RaceTask", "RaceResult", "multi_agent_tasks", "run_race", "run_multi_agent_table",
           "read_race_csv", "format_multi_agent_table", "format_per_circuit"]

logger = logging.getLogger(__name__)


def race_seed(base_seed: int, track: str, race: int) -> int:
    """The reset seed of race ``race`` on ``track``: :func:`~sofar_agents.evaluation.protocol.episode_seed` with
    rho 0 (deterministic across processes and platforms, the same for every strategy)."""
    return episode_seed(base_seed, track, 0.0, race)


@dataclass(frozen=True)
class RaceTask:
    """One race to run."""

    track: str
    strategy: Strategy
    seed: int
    """Reset seed."""
    cars: int = 4
    duration: float = DEFAULT_DURATION
    """Race duration [s]."""
    stack: str = "sofar"
    scenario: str = "paper"
    opponents: int = 0
    """Scripted opponents in the race besides the controlled cars (a mixed field)."""
    pinned_hash: str | None = None
    """A configuration hash given instead of the resolved one (``""``: rows written before the column)."""

    @property
    def config_hash(self) -> str:
        """The hash of the race's resolved configuration (:func:`~sofar_agents.evaluation.configs.race_config_hash`),
        or :attr:`pinned_hash`. Part of the resume key."""
        if self.pinned_hash is not None:
            return self.pinned_hash
        from sofar_agents.evaluation.configs import race_config_hash

        return race_config_hash(self.stack, self.scenario, self.duration, self.opponents)

    @property
    def key(self) -> tuple:
        return (self.track, self.strategy.name, self.strategy.policy_id, int(self.seed), int(self.cars),
                _fmt_float(self.duration), self.stack, self.scenario, int(self.opponents), self.config_hash)


@dataclass
class RaceResult:
    """What one race produced (one CSV row)."""

    track: str
    strategy: str
    policy_id: str
    seed: int
    cars: int
    duration: float
    stack: str
    scenario: str
    overtakes: int
    """Overtakes by controlled cars, of each other and of scripted opponents (each credited to the passer)."""
    collided: int
    """Controlled cars terminated by a collision (with another controlled car or a scripted opponent)."""
    off_track: int
    """Cars terminated by leaving the track."""
    stalled: int
    """Cars terminated by the stall rule."""
    success: int
    """Cars that reached the duration."""
    driven: float
    """Car-seconds driven over ``cars x duration`` [-]."""
    mean_gamma: float
    """Mean gamma over every car decision."""
    speed_factors: str
    """The cars' speed factors, space separated."""
    wall_time: float
    opponents: int = 0
    """Scripted opponents in the race (0: controlled cars only; absent in CSVs written before the column)."""
    config_hash: str = ""
    """The hash of the race environment's configuration ("": CSVs written before the column)."""
    miqp_failures: int = -1
    """Lateral plans in force that were the passing planner's fallback (its solver failed, the previous plan was
    taken; each car's ``miqp_failures`` counter), summed over the controlled cars (-1: not recorded, CSVs written
    before the column)."""

    @property
    def key(self) -> tuple:
        return (self.track, self.strategy, self.policy_id, int(self.seed), int(self.cars),
                _fmt_float(self.duration), self.stack, self.scenario, int(self.opponents), self.config_hash or "")


_FIELD_NAMES = [f.name for f in fields(RaceResult) if f.name != "config_hash"]
RACE_COLUMNS: tuple[str, ...] = tuple(_FIELD_NAMES[:_FIELD_NAMES.index("stack") + 1] + ["config_hash"]
                                      + _FIELD_NAMES[_FIELD_NAMES.index("stack") + 1:])
"""Columns of the per-race CSV (``config_hash`` next to ``stack``)."""
_RACE_ADDED = {"opponents": "0", "config_hash": "", "miqp_failures": "-1"}
"""Columns that CSVs of older layouts lack, with the value their rows stand for."""


def multi_agent_tasks(strategies: Sequence[Strategy], tracks: Sequence[str] = TRACKS, races: int = 4,
                      base_seed: int = 0, cars: int = 4, duration: float = DEFAULT_DURATION, stack: str = "sofar",
                      scenario: str = "paper", opponents: int = 0) -> list[RaceTask]:
    """Every (track, race, strategy), grouped by track; race ``e`` seeded with :func:`race_seed`."""
    return [RaceTask(track, strat, race_seed(base_seed, track, e), int(cars), float(duration), stack, scenario,
                     int(opponents))
            for track in tracks for e in range(int(races)) for strat in strategies]


def race_env(task: RaceTask, race_overrides: dict[str, Any] | None = None,
             stack_overrides: dict[str, Any] | None = None):
    """The PettingZoo environment of ``task`` (not reset): its circuit, cars, duration, controller preset,
    world and scripted opponents, with ``race_overrides`` / ``stack_overrides`` as in :func:`run_race`."""
    from sofar_env.config import make_env_config
    from sofar_env.multi_agent import parallel_env

    mixed = {"n_opponents": int(task.opponents)} if task.opponents else {}
    if stack_overrides:  # user keys: they win over the preset, the world and the multi-car defaults
        mixed["stack"] = dict(stack_overrides)
    return parallel_env(task.track, n_agents=task.cars, config=make_env_config(None, stack=task.stack),
                        race={**(race_overrides or {}), "duration": float(task.duration)},
                        scenario=task.scenario, timing_info=False, **mixed)


def run_race(task: RaceTask, policy: Any = None, race_overrides: dict[str, Any] | None = None,
             stack_overrides: dict[str, Any] | None = None) -> RaceResult:
    """Run one race; ``policy`` (obs -> gamma) defaults to ``task.strategy.build()``; ``race_overrides`` go
    into the ``race`` config (e.g. ``pace_range``), ``stack_overrides`` into the controller preset's
    (e.g. ``{"miqp": {"alongside_gap": 6.0}}``). The result's ``config_hash`` is that of the race's environment;
    without overrides, one that differs from ``task.config_hash`` raises ``RuntimeError`` before the reset."""
    from sofar_env.config import apply_overrides, make_env_config
    from sofar_env.multi_agent import parallel_env

    policy = task.strategy.build() if policy is None else policy
    t0 = time.perf_counter()
    env = race_env(task, race_overrides, stack_overrides)
    from sofar_env.config_hash import config_hash

    env_hash = config_hash(env.config)
    if task.config_hash and env_hash != task.config_hash and not (race_overrides or stack_overrides):
        env.close()
        raise RuntimeError(f"race {task.track}/{task.strategy.name}: the environment's config_hash is {env_hash}, "
                           f"the task's {task.config_hash}")
    obs, _ = env.reset(seed=int(task.seed))
    last: dict[str, dict] = {}
    gamma_sum, decisions = 0.0, 0
    while env.agents:
        actions = {a: np.asarray(policy(obs[a]), np.float32).reshape(1) for a in env.agents}
        obs, _, _, _, infos = env.step(actions)
        last.update(infos)
        gamma_sum += sum(float(info["gamma"]) for info in infos.values())
        decisions += len(infos)
    factors = env.speed_factors
    env.close()
    count = lambda key: sum(bool(info.get(key, False)) for info in last.values())  # noqa: E731
    return RaceResult(
        track=task.track, strategy=task.strategy.name, policy_id=task.strategy.policy_id, seed=int(task.seed),
        cars=int(task.cars), duration=float(task.duration), stack=task.stack, scenario=task.scenario,
        overtakes=sum(int(info["overtakes"]) for info in last.values()), collided=count("collision"),
        off_track=count("off_track"), stalled=count("stalled"), success=count("is_success"),
        driven=sum(float(info["sim_time"]) for info in last.values()) / (task.cars * task.duration),
        mean_gamma=gamma_sum / max(decisions, 1), speed_factors=" ".join(f"{f:.4f}" for f in factors),
        wall_time=time.perf_counter() - t0, opponents=int(task.opponents), config_hash=env_hash,
        miqp_failures=sum(int(info.get("miqp_failures", 0)) for info in last.values()),
    )


class RaceRunner:
    """The executor's worker body for races: :func:`run_race` with one policy per strategy, built on first use
    and kept, and the same ``race_overrides`` / ``stack_overrides`` for every race."""

    def __init__(self, race_overrides: dict[str, Any] | None = None,
                 stack_overrides: dict[str, Any] | None = None) -> None:
        self.race_overrides, self.stack_overrides = race_overrides, stack_overrides
        self.policies: dict[str, Any] = {}

    def run(self, task: RaceTask) -> RaceResult:
        if task.strategy.name not in self.policies:
            self.policies[task.strategy.name] = task.strategy.build()
        return run_race(task, self.policies[task.strategy.name], self.race_overrides, self.stack_overrides)

    def close(self) -> None:
        self.policies.clear()


class RaceJob(Job):
    """Races as an executor job: each finished race is appended to the per-race CSV ``csv_path`` (if given) and
    kept in ``results`` under its task's key; the races already in the CSV (by :attr:`RaceTask.key`, which holds the
    configuration hash) are skipped. ``runner``: a picklable factory of the worker body (:class:`RaceRunner`)."""

    unit = "races"

    def __init__(self, csv_path: str | os.PathLike | None, runner: Any = RaceRunner,
                 warm_up: str | None = None) -> None:
        self.csv_path = None if csv_path is None else Path(csv_path)
        self.runner, self.scenario = runner, warm_up
        self.results: dict[tuple, RaceResult] = {}

    def done_keys(self) -> set:
        return set() if self.csv_path is None else {r.key for r in read_race_csv(self.csv_path)}

    def open(self, pending) -> None:
        if self.scenario is not None:
            from sofar_env.compile import warm_up

            warm_up([self.scenario])  # compile here, not inside the progress bar's estimate

    def write(self, task: RaceTask, payload: RaceResult, stats: RunStats) -> None:
        if self.csv_path is not None:
            _append(self.csv_path, payload)
        self.results[task.key] = payload

    def describe(self, task: RaceTask) -> str:
        return f"race {task.track}/{task.strategy.name} seed={task.seed}"


# ---------------------------------------------------------------------------- CSV


def read_race_csv(path: str | os.PathLike) -> list[RaceResult]:
    """The complete rows of a per-race CSV, read by :func:`~sofar_agents.evaluation.results.read_csv_rows` (the
    Table I reader): a torn last line and incomplete rows anywhere are dropped, a file of another kind raises
    ``ValueError`` naming it, a row whose values do not parse is skipped with a warning. A CSV from before the
    ``opponents`` column stands for races without scripted opponents."""
    out = []
    types = {f.name: f.type for f in fields(RaceResult)}
    text = [name for name, kind in types.items() if kind == "str"]  # may be empty (policy_id of a fixed gamma)
    for row in read_csv_rows(path, RACE_COLUMNS, added=_RACE_ADDED, may_be_empty=text, kind="per-race CSV"):
        try:
            values = {name: int(row[name]) if kind == "int" else float(row[name]) if kind == "float" else row[name]
                      for name, kind in types.items()}
        except ValueError:
            logger.warning("skipping an unreadable row of %s: %s", path, row)
            continue
        out.append(RaceResult(**values))
    return out


def _append(path: Path, result: RaceResult) -> None:
    new = not path.exists() or path.stat().st_size == 0
    rows, mode = [result], "a"
    if not new:
        text = path.read_text()
        if not text.endswith("\n"):  # drop a torn last line
            write_text_atomic(path, text[: text.rfind("\n") + 1])
        if text.split("\n", 1)[0].split(",") != list(RACE_COLUMNS):  # an older layout: rewrite in this one
            rows, new, mode = read_race_csv(path) + rows, True, "w"
    buf = io.StringIO()
    writer = csv.DictWriter(buf, RACE_COLUMNS, lineterminator="\n")
    if new:
        writer.writeheader()
    for row in rows:
        writer.writerow({k: ((exact_text(v) if k == "duration" else f"{v:.6g}") if isinstance(v, float) else v)
                         for k, v in asdict(row).items()})  # the duration, a key column, exactly
    with open(path, mode) as f:
        f.write(buf.getvalue())
        f.flush()


# ---------------------------------------------------------------------------- tables


def _summary_cells(rows: Sequence[RaceResult]) -> str:
    n = len(rows)
    car_races = sum(r.cars for r in rows)
    mean = lambda attr: sum(getattr(r, attr) for r in rows) / n  # noqa: E731
    with_collision = 100.0 * sum(r.collided > 0 for r in rows) / n
    return (f"{n} | {mean('overtakes'):.2f} | {with_collision:.0f} | {mean('collided'):.2f} | "
            f"{mean('off_track'):.2f} | {mean('stalled'):.2f} | {100.0 * sum(r.success for r in rows) / car_races:.0f} | "
            f"{100.0 * mean('driven'):.0f} | {mean('mean_gamma'):.2f}")


_HEADER = ("races | overtakes / race | races with a collision [%] | colliding cars / race | off-track cars / race | "
           "stalled cars / race | success per car [%] | driven [%] | mean γ")


def format_multi_agent_table(rows: Sequence[RaceResult], strategies: Sequence[str], labels: dict[str, str] | None = None
                             ) -> str:
    """One line per strategy over all its races."""
    labels = labels or {}
    lines = [f"| strategy | {_HEADER} |", "|---|" + "---:|" * 9]
    for name in strategies:
        mine = [r for r in rows if r.strategy == name]
        if mine:
            lines.append(f"| {labels.get(name, name)} | {_summary_cells(mine)} |")
    return "\n".join(lines)


def format_per_circuit(rows: Sequence[RaceResult], strategies: Sequence[str], tracks: Sequence[str],
                       labels: dict[str, str] | None = None) -> str:
    """One line per (circuit, strategy)."""
    labels = labels or {}
    lines = [f"| circuit | strategy | {_HEADER} |", "|---|---|" + "---:|" * 9]
    for track in tracks:
        for name in strategies:
            mine = [r for r in rows if r.strategy == name and r.track == track]
            if mine:
                lines.append(f"| {track} | {labels.get(name, name)} | {_summary_cells(mine)} |")
    return "\n".join(lines)


# ---------------------------------------------------------------------------- the table


@dataclass
class MultiAgentReport:
    """Outcome of :func:`run_multi_agent_table`."""

    markdown: str
    csv_path: Path
    markdown_path: Path
    rows: list[RaceResult]
    completed: int
    skipped: int
    elapsed: float
    missing: int = 0
    """Races of the table without a row in the CSV (they failed, or were lost with a worker process that died):
    rerunning the same command with the same output folder runs them."""
    expected: int = 0
    """Races of the table."""
    stats: RunStats = field(default_factory=RunStats)
    """What the executor did in this run (``failed``, ``missing``; see
    :func:`~sofar_agents.executor.incomplete_message`)."""


def run_multi_agent_table(strategies: Sequence[Strategy], out_dir: str | os.PathLike = "results/multi_agent", *,
                          tracks: Sequence[str] = TRACKS, races: int = 4, base_seed: int = 0, cars: int = 4,
                          duration: float = DEFAULT_DURATION, stack: str = "sofar", scenario: str = "paper",
                          workers: int | None = 1, prefix: str = "multi_agent", progress: bool = True,
                          opponents: int = 0) -> MultiAgentReport:
    """Run (or resume) the races into ``out_dir/<prefix>_races.csv`` and write ``<prefix>.md``.

    The races run on the executor (:mod:`sofar_agents.executor`) with the resume and fault behaviour of Table I:
    ``workers``: None for one per CPU, below 1 raises ValueError; with ``workers`` > 1 the races run in worker
    processes that end with this process (even when it is killed). A race that raises, or is lost with a worker
    process that died, is logged, left out of the CSV and counted (``stats.failed``, ``stats.missing``; in all,
    ``missing`` of the report, and its Markdown says the table is incomplete) instead of raising; a rerun runs it.
    """
    from sofar_agents.executor.core import check_workers

    check_workers(workers, "local")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    csv_path = out / f"{prefix}_races.csv"
    tasks = multi_agent_tasks(strategies, tracks, races, base_seed, cars, duration, stack, scenario, opponents)
    from sofar_agents.evaluation.configs import check_one_config, race_config, write_config_json

    write_config_json(out, [race_config(stack, scenario, float(duration), int(opponents))])
    stats = execute(tasks, RaceJob(csv_path, RaceRunner, warm_up=scenario), workers=workers, progress=progress)
    elapsed = stats.elapsed
    n_workers = max(1, int(workers or os.cpu_count() or 1))
    wanted = {t.key for t in tasks}
    all_rows = read_race_csv(csv_path)
    rows = [r for r in all_rows if r.key in wanted]
    check_one_config(rows, lambda r: r.strategy, str(csv_path))
    by_rest = {k[:-1]: k[-1] for k in wanted}
    other = sum(1 for r in all_rows if r.key[:-1] in by_rest and by_rest[r.key[:-1]] != r.key[-1])
    names = [s.name for s in strategies]
    labels = {s.name: s.label for s in strategies}
    field_text = f"{cars} cars" + (f" and {opponents} scripted opponents" if opponents else "")
    settings = (f"{field_text}, {duration:g} s races, circuits {', '.join(tracks)}, {races} races per circuit "
                f"(base seed {base_seed}), "
                f"controller {stack}, world {scenario}. Generated {time.strftime('%Y-%m-%d %H:%M')}.")
    parts = ["# Multi-agent races", "", settings, "",
             "Every car of a race is driven by the same strategy from its own observation; the race's seed fixes the "
             "grid and the cars' pace, so the strategies meet the same fields. " + (
                 "Overtakes are between controlled cars (credited to the passer); every collision is between two "
                 "controlled cars (both terminate)" if not opponents else
                 "Overtakes are passes by controlled cars, of each other and of the scripted opponents (credited to "
                 "the passer; a scripted car is not respawned, so lapping it is another pass); a collision terminates "
                 "the controlled cars involved") + "; success per car: cars that reached the duration.", "",
             format_multi_agent_table(rows, names, labels), "", "## Per circuit", "",
             format_per_circuit(rows, names, tracks, labels)]
    if other:
        parts += ["", f"**Left out:** {other} rows of {csv_path.name} with another configuration hash or none "
                  "(written before the column): races of another configuration, not mixed with these."]
    missing = len(tasks) - len(rows)
    if missing:
        parts += ["", f"**Incomplete:** {missing} of {len(tasks)} races are missing; rerun the same command."]
    ran = stats.requested - stats.skipped
    parts += ["", f"{ran} races run ({stats.skipped} taken from the CSV) with {n_workers} "
              f"worker{'' if n_workers == 1 else 's'} in {elapsed:.0f} s."]
    md = "\n".join(parts) + "\n"
    md_path = out / f"{prefix}.md"
    write_text_atomic(md_path, md)
    return MultiAgentReport(md, csv_path, md_path, rows, ran, stats.skipped, elapsed, missing, len(tasks), stats)
