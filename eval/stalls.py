"""Why does the ego stall? Replay stalled episodes (or run a seed set), record the slow phase, classify each stall.

    python eval/stalls.py --replay results/interactive_dense/end_rows/sofar-recover/table1_episodes.csv \
        --out results/interactive_dense/stalls/committed
    python eval/stalls.py --stacks sofar-1 sofar-recover --gammas 0.05 0.5 --rhos 0.1 0.2 0.3 --episodes 2 \
        --seed 7301 --out results/interactive_dense/stalls/seed7301
    python eval/stalls.py --report results/interactive_dense/stalls/seed7301     # re-make stalls.md, nothing runs

``--replay`` runs every stalled fixed-gamma episode of the given per-episode CSVs (``eval/table.py``) again on
this machine; without it, Table I's episodes of each preset and gamma on a base seed (the dense interactive
world by default) are run and their stalls caught. Each stall is classified by the rules of
``sofar_agents.evaluation.stalls`` (its docstring lists them). Writes to ``--out``: ``stalls.csv`` (one row per
episode: outcome, class, evidence), ``records.csv.gz`` (the step records of every stall: its 20 s below 1 m/s and 2 s before),
for a seed set also ``table1_episodes.csv`` (the rows of ``eval/table.py``, for ``eval/paired.py --by-stack``),
and ``stalls.md`` (the tables). A rerun with the same ``--out`` skips the episodes already in ``stalls.csv``.
One process; the logic is in sofar_agents.evaluation.stalls.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import gzip
import io
import logging
import sys
import time
from collections import Counter, defaultdict
from pathlib import Path

from sofar_agents import evaluation as ev
from sofar_agents.cli_types import gamma_value, nonneg_float, nonneg_int, positive_int
from sofar_agents.evaluation import stall_rows as sr
from sofar_agents.evaluation import stalls as st
from sofar_agents.evaluation.files import write_text_atomic
from sofar_agents.evaluation.protocol import exact_text
from sofar_env.stack.config import STACK_PRESETS

logger = logging.getLogger("stalls")


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--replay", nargs="+", default=None, metavar="CSV",
                   help="replay the stalls of these per-episode CSVs (table1_episodes.csv) instead of running a seed set")
    p.add_argument("--report", default=None, metavar="FOLDER",
                   help="re-make FOLDER/stalls.md from its stalls.csv and records.csv.gz (no episode is run)")
    p.add_argument("--out", default="results/stalls", help="output folder (default results/stalls)")
    p.add_argument("--stacks", nargs="+", default=None,
                   help="controller presets (default: sofar sofar-1, the default and its former version; with "
                        "--replay: every preset in the CSVs)")
    p.add_argument("--replay-with", default=None, metavar="PRESET", choices=list(STACK_PRESETS),
                   help="with --replay: run the stalled episodes with this controller preset instead of their own "
                        "(do a candidate's episodes still stall where the committed preset's did?), one of "
                        + ", ".join(STACK_PRESETS))
    p.add_argument("--limit", type=positive_int, default=None, help="with --replay: at most this many stalls per CSV")
    p.add_argument("--gammas", nargs="+", type=gamma_value, default=[0.05, 0.5], help="fixed gammas of the seed set")
    p.add_argument("--tracks", nargs="+", default=list(ev.TRACKS), help="circuits of the seed set")
    p.add_argument("--rhos", nargs="+", type=nonneg_float, default=[0.1, 0.2, 0.3], help="pace ratios of the seed set")
    p.add_argument("--episodes", type=positive_int, default=3, help="episodes per (circuit, rho) of the seed set")
    p.add_argument("--seed", type=nonneg_int, default=7301, help="base seed of the seed set's episode seeds")
    p.add_argument("--opponents", type=nonneg_int, default=8, help="opponents per episode of the seed set")
    p.add_argument("--scenario", default="interactive", help="world of the seed set")
    p.add_argument("--log-level", default="INFO")
    args = p.parse_args(argv)
    if args.replay and args.report:
        p.error("--replay and --report exclude each other")
    if args.replay_with and not args.replay:
        p.error("--replay-with needs --replay")
    return args


def _key(row) -> tuple:
    return (str(row["label"]), str(row["stack"]), str(row["track"]), exact_text(float(row["rho"])),
            int(row["seed"]), exact_text(float(row["gamma"])))


RECORDS = "records.csv.gz"
"""The step records of a folder's stalls (appended as gzip members: one file, read as one)."""


def _append(path: Path, columns, rows) -> None:
    """Append ``rows`` to the CSV ``path`` (a header first when it is new); ``ValueError`` naming the file when it
    has other columns (written by an older version: use another ``--out``)."""
    new = not path.exists() or path.stat().st_size == 0
    if not new:
        with (gzip.open(path, "rt", newline="") if path.suffix == ".gz" else open(path, newline="")) as f:
            header = next(csv.reader(f), [])
        if header != list(columns):
            raise ValueError(f"{path} has the columns of another version ({len(header)} against {len(columns)}); "
                             f"use another --out")
    with (gzip.open(path, "at", newline="") if path.suffix == ".gz" else open(path, "a", newline="")) as f:
        w = csv.DictWriter(f, fieldnames=list(columns), lineterminator="\n", extrasaction="ignore")
        if new:
            w.writeheader()
        w.writerows(rows)


def _episode_row(result) -> dict:
    row = result.to_row()
    out = {}
    for k, v in row.items():
        if isinstance(v, bool):
            v = int(v)
        elif isinstance(v, float):
            v = exact_text(v) if k in ("rho", "duration") else f"{v:.6g}"
        out[k] = v
    return out


def run_tasks(tasks, labels, out: Path, episodes_csv: bool) -> float:
    """Run the tasks not yet in ``out/stalls.csv``, appending each episode's rows; the wall time [s]."""
    done = set()
    if (out / "stalls.csv").exists():
        with open(out / "stalls.csv", newline="") as f:
            done = {_key(r) for r in csv.DictReader(f)}
    todo = [(t, lab) for t, lab in zip(tasks, labels)
            if (lab, t.stack, t.track, exact_text(t.rho), t.seed,
                exact_text(t.strategy.gamma)) not in done]
    logger.info("%d episodes, %d already in %s", len(tasks), len(tasks) - len(todo), out / "stalls.csv")
    t0 = time.perf_counter()
    envs: dict = {}  # the environments of the current circuit, one per preset and settings
    try:
        for t, lab in todo:
            if envs and next(iter(envs))[0] != t.track:
                for env in envs.values():
                    env.close()
                envs.clear()
            if t.env_key not in envs:
                envs[t.env_key] = ev.make_env(t.track, use_miqp=t.use_miqp, duration=t.duration, stack=t.stack,
                                              scenario=t.scenario)
            t1 = time.perf_counter()
            rep = st.record_episode(t, lab, envs[t.env_key])
            logger.info("%s %s rho %g seed %d gamma %g: %s at %.1f s %s (%.1f s)", t.stack, t.track, t.rho, t.seed,
                        t.strategy.gamma, sr.report_rows([rep])[0]["outcome"], rep.result.sim_time, rep.cls,
                        time.perf_counter() - t1)
            _append(out / "stalls.csv", sr.REPORT_COLUMNS, sr.report_rows([rep]))
            if rep.records:
                _append(out / RECORDS, sr.RECORD_COLUMNS, sr.record_rows(rep))
            if episodes_csv:
                _append(out / "table1_episodes.csv", ev.EPISODE_COLUMNS, [_episode_row(rep.result)])
    finally:
        for env in envs.values():
            env.close()
    return time.perf_counter() - t0


def markdown(rows) -> str:
    """The tables of a stalls.csv: counts per class per (label, preset), then every stall with its evidence."""
    groups = defaultdict(list)
    for r in rows:
        groups[(r["label"], r["stack"])].append(r)
    classes = list(st.CLASSES)
    lines = ["| episodes | preset | episodes run | stalls | " + " | ".join(f"`{c}`" for c in classes) + " |",
             "|---|---|---:|---:|" + "---:|" * len(classes)]
    for (label, stack), rs in sorted(groups.items()):
        stalled = [r for r in rs if r["outcome"] == "stalled"]
        n = Counter(r["cls"] for r in stalled)
        lines.append(f"| {label} | `{stack}` | {len(rs)} | {len(stalled)} | "
                     + " | ".join(str(n.get(c, 0)) for c in classes) + " |")
    not_rep = [r for r in rows if r["label"].startswith("committed") and r["outcome"] != "stalled"]
    text = "\n".join(lines) + "\n"
    if not_rep:
        text += (f"\n{len(not_rep)} committed stall(s) did not stall in the replay: "
                 + ", ".join(f"{r['stack']} {r['track']} rho {r['rho']} seed {r['seed']} gamma {r['gamma']} "
                             f"({r['outcome']} at {r['sim_time']} s)" for r in not_rep) + ".\n")
    cols = ("label", "stack", "track", "rho", "seed", "gamma", "sim_time", "cls", "decision", "fallback", "follow",
            "away", "e", "row_room", "turn_room", "corner_room", "v_next", "v_plan", "v_ref", "accel", "gap_ahead",
            "v_ahead", "room_beside", "n", "n_ref", "track_slack", "barrier_slack", "h_min")
    text += "\nEvery stall (medians over the last 10 s; `fallback`, `follow`: shares of those steps):\n\n"
    text += "| " + " | ".join(cols) + " |\n|" + "---|" * len(cols) + "\n"
    for r in rows:
        if r["outcome"] == "stalled":
            text += "| " + " | ".join(_fmt(r.get(c, "")) for c in cols) + " |\n"
    return text


def _fmt(v) -> str:
    try:
        x = float(v)
    except (TypeError, ValueError):
        return str(v)
    if x != x or abs(x) == float("inf"):
        return "–"
    return f"{x:.3g}" if abs(x) < 1e4 else f"{x:.0f}"


def reclassify(out: Path) -> list[dict]:
    """The rows of ``out/stalls.csv``, each stall classified again from ``out/records.csv.gz``
    (:func:`~sofar_agents.evaluation.stall_rows.records_from_rows`: the rooms measured by this version); the CSV is
    rewritten with them."""
    with open(out / "stalls.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    if not (out / RECORDS).exists():
        return rows
    with gzip.open(out / RECORDS, "rt", newline="") as f:
        records = sr.records_from_rows(csv.DictReader(f))
    for row in rows:
        key = (row["track"], row["rho"], row["seed"], row["stack"], row["gamma"])
        if row["outcome"] == "stalled" and key in records:
            row["cls"], evidence = st.classify(records[key])
            row.update({c: evidence[c] for c in sr.REPORT_COLUMNS if c in evidence})
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(sr.REPORT_COLUMNS), lineterminator="\n", extrasaction="ignore")
    w.writeheader()
    w.writerows(rows)
    write_text_atomic(out / "stalls.csv", buf.getvalue())
    return rows


def write_report(out: Path, extra: str = "") -> str:
    rows = reclassify(out)
    text = markdown(rows) + extra
    ev.write_markdown(out / "stalls.md", text)
    return text


def main(argv=None) -> int:
    args = parse_args(argv)
    logging.basicConfig(level=args.log_level.upper(), format="%(asctime)s %(message)s", datefmt="%H:%M:%S")
    if args.report:
        print(write_report(Path(args.report)))
        return 0
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    try:
        if args.replay:
            tasks, labels = [], []
            for name, rows in ev.read_seed_sets(args.replay).items():
                found = sr.stalled_tasks(rows, args.stacks)[:args.limit]
                if args.replay_with:
                    found = [dataclasses.replace(t, stack=args.replay_with, pinned_hash=None) for t in found]
                logger.info("%s: %d stalls", name, len(found))
                tasks += found
                labels += [f"committed {name[name.find('results/'):] if 'results/' in name else name}"] * len(found)
        else:
            tasks = sr.fresh_tasks(args.stacks or ["sofar", "sofar-1"], args.gammas, args.tracks, args.rhos,
                                   args.episodes, args.seed, args.opponents, args.scenario)
            labels = [f"fresh seed {args.seed}"] * len(tasks)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    try:
        wall = run_tasks(tasks, labels, out, episodes_csv=not args.replay)
    except ValueError as exc:  # a stalls.csv of another version in --out
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if not (out / "stalls.csv").exists():  # nothing ran and nothing was there: no report to make
        print(f"no stalled episode to replay in {', '.join(args.replay or [])}: nothing written")
        return 0
    command = "python eval/stalls.py " + " ".join(argv if argv is not None else sys.argv[1:])
    print(write_report(out, f"\n{len(tasks)} episodes; this call ran for {wall:.0f} s in one process. "
                            f"Command: `{command}`\n"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
