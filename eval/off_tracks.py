"""Why does the ego leave the track? Replay the off-track episodes of per-episode CSVs, record, classify.

    python eval/off_tracks.py --replay results/dynamic/candidate_sofar_6/table1_episodes.csv \
        results/dynamic/candidate_sofar_10/table1_episodes.csv --out results/dynamic/off_tracks/protocol

Runs every fixed-gamma episode of the given CSVs (``eval/table.py``'s ``table1_episodes.csv``) that ended off the
track again on this machine, keeps its last 4 s step by step and classifies the departure by the rules of
``sofar_agents.evaluation.off_tracks`` (its docstring lists them: ``spin``, ``planned``, ``left_plan``). Writes
to ``--out``, each file atomically: ``off_tracks.csv`` (one row per episode: outcome, class, evidence),
``records.csv.gz`` (the step records of every departure) and ``off_tracks.md`` (the tables). A rerun with the same
``--out`` skips the episodes already in ``off_tracks.csv``. One process.
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
from sofar_agents.cli_types import positive_int
from sofar_agents.evaluation import off_tracks as ot
from sofar_agents.evaluation.files import write_bytes_atomic, write_text_atomic
from sofar_env.stack.config import STACK_PRESETS

logger = logging.getLogger("off_tracks")

RECORDS = "records.csv.gz"


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--replay", nargs="+", required=True, metavar="CSV",
                   help="per-episode CSVs (table1_episodes.csv) whose off-track episodes are replayed")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--stacks", nargs="+", default=None, help="only the rows of these presets (default: every one)")
    p.add_argument("--replay-with", default=None, metavar="PRESET", choices=list(STACK_PRESETS),
                   help="run the episodes with this controller preset instead of their own, one of "
                        + ", ".join(STACK_PRESETS))
    p.add_argument("--limit", type=positive_int, default=None, help="at most this many episodes per CSV")
    p.add_argument("--log-level", default="INFO")
    return p.parse_args(argv)


def _key(row) -> tuple:
    return tuple(str(row[c]) for c in ("label", "stack", "track", "rho", "seed", "gamma"))


def _read(path: Path, columns) -> list[dict]:
    """The rows of a CSV this script wrote (``ValueError`` naming it when it has other columns)."""
    if not path.exists():
        return []
    with (gzip.open(path, "rt", newline="") if path.suffix == ".gz" else open(path, newline="")) as f:
        reader = csv.DictReader(f)
        if list(reader.fieldnames or []) != list(columns):
            raise ValueError(f"{path} has the columns of another version; use another --out")
        return list(reader)


def _csv_text(columns, rows) -> str:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(columns), lineterminator="\n", extrasaction="ignore")
    w.writeheader()
    w.writerows(rows)
    return buf.getvalue()


def run_tasks(tasks, labels, out: Path) -> float:
    """Run the tasks not yet in ``out/off_tracks.csv``; rewrite its files after each episode; the wall time [s]."""
    rows = _read(out / "off_tracks.csv", ot.REPORT_COLUMNS)
    records = _read(out / RECORDS, ot.RECORD_COLUMNS)
    done = {_key(r) for r in rows}
    t0 = time.perf_counter()
    for task, label in zip(tasks, labels):
        ident = {"label": label, "stack": task.stack, "track": task.track, "rho": f"{task.rho:g}",
                 "seed": task.seed, "gamma": f"{task.strategy.gamma:g}"}
        if _key(ident) in done:
            continue
        rep = ot.record_off_track(task, label)
        logger.info("%s %s rho %g seed %d gamma %g: %s at %.1f s", task.stack, task.track, task.rho, task.seed,
                    task.strategy.gamma, rep.cls or "stayed on the track", rep.result.sim_time)
        rows += ot.report_rows([rep])
        records += ot.record_rows(rep)
        done.add(_key(ident))
        write_bytes_atomic(out / RECORDS, gzip.compress(_csv_text(ot.RECORD_COLUMNS, records).encode(), mtime=0))
        write_text_atomic(out / "off_tracks.csv", _csv_text(ot.REPORT_COLUMNS, rows))
    return time.perf_counter() - t0


def markdown(rows) -> str:
    """Counts per class per (label, preset), then every departure with its evidence."""
    groups = defaultdict(list)
    for r in rows:
        groups[(r["label"], r["stack"])].append(r)
    classes = list(ot.CLASSES)
    lines = ["| episodes | preset | replayed | off the track | " + " | ".join(f"`{c}`" for c in classes)
             + " | on the outside of a turn | braking (mean accel < -3 m/s², last 1 s) |",
             "|---|---|---:|---:|" + "---:|" * len(classes) + "---:|---:|"]
    for (label, stack), rs in sorted(groups.items()):
        off = [r for r in rs if r["outcome"] == "off_track"]
        n = Counter(r["cls"] for r in off)
        outside = sum(r["outside"] == "1" for r in off)
        braking = sum(float(r["accel"]) < -3.0 for r in off)
        lines.append(f"| {label} | `{stack}` | {len(rs)} | {len(off)} | "
                     + " | ".join(str(n.get(c, 0)) for c in classes) + f" | {outside} | {braking} |")
    text = "\n".join(lines) + "\n"
    cols = ("stack", "track", "rho", "seed", "gamma", "sim_time", "cls", "v", "lat_demand", "side", "outside", "slip",
            "accel", "lat_slack", "plan_move", "plan_room", "nearest", "following", "e")
    text += ("\nEvery departure (at its last step; over the last 2 s `slip`, the largest side-slip [rad], "
             "`lat_slack`, the MPC's largest lateral-acceleration slack [m/s²], and `plan_move`, the range of the "
             "plan's final lateral offset [m]; over the last 1 s `accel`, the mean commanded acceleration [m/s²], "
             "and `plan_room`, the smallest room of the planned footprint to an edge [m]):\n\n")
    text += "| " + " | ".join(cols) + " |\n|" + "---|" * len(cols) + "\n"
    for r in rows:
        if r["outcome"] == "off_track":
            text += "| " + " | ".join(str(r.get(c, "")) for c in cols) + " |\n"
    stayed = [r for r in rows if r["outcome"] != "off_track"]
    if stayed:
        text += (f"\n{len(stayed)} episode(s) did not leave the track in the replay: "
                 + ", ".join(f"{r['stack']} {r['track']} rho {r['rho']} seed {r['seed']} gamma {r['gamma']} "
                             f"({r['outcome']} at {r['sim_time']} s)" for r in stayed) + ".\n")
    return text


def main(argv=None) -> int:
    args = parse_args(argv)
    logging.basicConfig(level=args.log_level.upper(), format="%(asctime)s %(message)s", datefmt="%H:%M:%S")
    out = Path(args.out)
    tasks, labels = [], []
    try:
        for name, rows in ev.read_seed_sets(args.replay).items():
            found = ot.off_track_tasks(rows, args.stacks)[:args.limit]
            if args.replay_with:
                found = [dataclasses.replace(t, stack=args.replay_with, pinned_hash=None) for t in found]
            logger.info("%s: %d off-track episodes", name, len(found))
            tasks += found
            labels += [name[name.find("results/"):] if "results/" in name else name] * len(found)
        out.mkdir(parents=True, exist_ok=True)
        wall = run_tasks(tasks, labels, out)
        rows = _read(out / "off_tracks.csv", ot.REPORT_COLUMNS)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if not rows:
        print(f"no off-track episode in {', '.join(args.replay)}: nothing written")
        return 0
    command = "python eval/off_tracks.py " + " ".join(argv if argv is not None else sys.argv[1:])
    text = markdown(rows) + (f"\n{len(tasks)} episodes; this call ran for {wall:.0f} s in one process. "
                             f"Command: `{command}`\n")
    ev.write_markdown(out / "off_tracks.md", text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
