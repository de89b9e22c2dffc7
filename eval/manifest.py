"""Experiments as manifests (experiments/NAME.toml): run one, check them all, verify old rows.

    python eval/manifest.py list [--stack sofar]       # the manifests (of one controller) and the hash of each
    python eval/manifest.py run NAME [NAME ...] [--workers N]   # run (or resume) each into its folder, in one pass
    python eval/manifest.py check                      # every manifest resolves; committed rows carry its hash
    python eval/manifest.py verify NAME [--rows 2]     # re-make its shortest rows (races) per circuit in a temporary folder
    python eval/manifest.py verify NAME --backfill     # ... and, when they match, give its rows the manifest's hash
    python eval/manifest.py adopt NAME --rows-from CANDIDATE   # start NAME's table from a candidate's fixed-gamma rows

``check`` exits with status 1 when a committed CSV holds rows of another configuration hash than its
manifest's (the defaults moved since: re-run the manifest into another folder, or restore the old
defaults); rows without a hash (written before the column) are reported, not an error. ``verify`` exits
with status 1 when a re-made row differs from the committed one in any column of the committed file but
``wall_time``. ``--backfill`` refuses a CSV of the first format (without the ``stack`` column), whose
``stalled`` is unknown. For an interventions manifest a unit is a failed episode with all its replays:
``--rows N`` re-makes the N episodes of the fewest replayed steps (over all circuits), and ``--backfill``
appends the ``config_hash`` column where ``interventions.csv`` has it (last).
The logic lives in sofar_agents.evaluation.manifest.
"""

from __future__ import annotations

import argparse
import logging
import sys
import tempfile
import time
from pathlib import Path

from sofar_agents.cli_types import int_at_least
from sofar_agents.evaluation import manifest as mf

logger = logging.getLogger("manifest")

ROOT = Path(__file__).resolve().parent.parent
FOLDER = ROOT / "experiments"


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], epilog=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--folder", default=str(FOLDER), help="folder of the manifests (default experiments/)")
    sub = p.add_subparsers(dest="command", required=True)
    ls = sub.add_parser("list", help="the manifests and their configuration hashes")
    ls.add_argument("--stack", default=None, help="only the manifests of this controller preset")
    r = sub.add_parser("run", help="run manifests into their results folders, one after the other")
    r.add_argument("name", nargs="+", help="manifest names; each is run (or resumed) and its wall time logged")
    r.add_argument("--workers", type=int_at_least(1), default=None, help="worker processes (default: one per CPU)")
    r.add_argument("--out", default=None, help="another results folder (default: the manifest's; one manifest only)")
    r.add_argument("--no-progress", action="store_true")
    sub.add_parser("check", help="compare every manifest's hash with the hashes its committed rows carry")
    v = sub.add_parser("verify", help="re-make the shortest committed rows of a manifest and compare them")
    v.add_argument("name")
    v.add_argument("--rows", type=int_at_least(1), default=2,
                   help="how many rows per circuit (the shortest episodes); interventions: how many failed episodes "
                        "(the cheapest to replay)")
    v.add_argument("--backfill", action="store_true",
                   help="when every re-made row matches, give the CSV's rows the manifest's hash: rows without one "
                        "(written before the column), or rows of one other hash (a configuration whose hash moved "
                        "without changing the episodes)")
    a = sub.add_parser("adopt", help="copy into a manifest's CSV the fixed-gamma rows another manifest of the same "
                                     "configuration hash ran (a candidate's, when the default moves to it), relabelled")
    a.add_argument("name", help="the manifest whose table the rows start")
    a.add_argument("--rows-from", required=True, metavar="SOURCE",
                   help="the manifest whose rows are copied (its episodes that are the target's)")
    p.add_argument("--log-level", default="INFO")
    return p.parse_args(argv)


def _load(folder: Path, name: str) -> mf.Manifest:
    path = folder / (name if name.endswith(".toml") else f"{name}.toml")
    if not path.is_file():
        raise SystemExit(f"no manifest {path}; see: python eval/manifest.py list")
    return mf.load_manifest(path)


def shortest_rows(m: mf.Manifest, n: int, root: Path = ROOT) -> list[dict[str, str]]:
    """The ``n`` committed rows of ``m`` with the fewest steps on each circuit (races: the least driven; the
    cheapest to re-make); rows of the CSV that are not episodes of ``m`` (other runs into the same folder) are not
    candidates."""
    ids = mf.episode_ids(m, root)
    mine = [r for r in mf.raw_rows(root / m.out / m.csv_name, m.kind) if mf.row_episode(m, r) in ids]
    if m.kind == "interventions":
        return cheapest_replays(m, mine, n)
    if m.kind == "standing-start":  # placements: no strategy or seed
        rows = sorted(mine, key=lambda r: (mf.row_length(m, r), mf.row_id(m, r)))
    else:
        rows = sorted(mine, key=lambda r: (mf.row_length(m, r), r["strategy"], r["seed"]))
    per_track: dict[str, list[dict[str, str]]] = {}
    for r in rows:
        mine = per_track.setdefault(r["track"], [])
        if len(mine) < n:
            mine.append(r)
    return [r for track in sorted(per_track) for r in per_track[track]]


def cheapest_replays(m: mf.Manifest, rows: list[dict[str, str]], n: int) -> list[dict[str, str]]:
    """Every row (replay) of the ``n`` episodes of ``rows`` (an ``interventions.csv``) with the fewest steps in
    all, in file order."""
    cost: dict[tuple, float] = {}
    for r in rows:
        key = mf.row_episode(m, r)
        cost[key] = cost.get(key, 0.0) + mf.row_length(m, r)
    chosen = set(sorted(cost, key=lambda k: (cost[k], k))[:n])
    return [r for r in rows if mf.row_episode(m, r) in chosen]


def main(argv=None) -> int:
    args = parse_args(argv)
    logging.basicConfig(level=args.log_level.upper(), format="%(message)s")
    folder = Path(args.folder)
    if args.command == "list":
        for path in mf.manifest_paths(folder):
            m = mf.load_manifest(path)
            if args.stack is not None and m.stack != args.stack:
                continue
            logger.info("%s: %s %s (stack %s, world %s) -> %s", m.name, m.kind, m.config_hash, m.stack, m.scenario,
                        m.out)
        return 0
    if args.command == "check":
        bad = 0
        for path in mf.manifest_paths(folder):
            result = mf.check_manifest(mf.load_manifest(path), ROOT)
            (logger.error if result.status == "mismatch" else logger.info)("%s", result.line())
            bad += result.status == "mismatch"
        return 1 if bad else 0
    if args.command == "run":
        manifests = [_load(folder, name) for name in args.name]  # every name checked before anything runs
        if args.out is not None and len(manifests) > 1:
            raise SystemExit("--out takes one manifest")
        walls = []
        for m in manifests:
            t0 = time.perf_counter()
            report = mf.run_manifest(m, ROOT, workers=args.workers, out=args.out, progress=not args.no_progress)
            walls.append((m.name, time.perf_counter() - t0))
            logger.info("%s", getattr(report, "markdown", report) or "")  # a table's report, or the probe's text
        for name, wall in walls:
            logger.info("%s: %.0f s", name, wall)
        return 0
    if args.command == "adopt":
        from sofar_agents.evaluation.manifest_adopt import adopt_rows

        target, source = _load(folder, args.name), _load(folder, args.rows_from)
        try:
            n = adopt_rows(target, source, ROOT)
        except ValueError as err:
            logger.error("%s: nothing adopted: %s", target.name, err)
            return 1
        logger.info("%s: %d rows of %s adopted (config_hash %s); run it to make the rest", target.name, n,
                    source.name, target.config_hash)
        return 0
    m = _load(folder, args.name)
    rows = shortest_rows(m, args.rows)
    if not rows:
        logger.error("%s: no committed rows in %s", m.name, ROOT / m.out / m.csv_name)
        return 1
    with tempfile.TemporaryDirectory() as tmp:
        diffs = mf.rerun_rows(m, ROOT, rows, tmp)
    for d in diffs:
        logger.error("%s", d)
    if diffs:
        logger.error("%s: %d differences; the committed rows are not re-made by the current code", m.name, len(diffs))
        return 1
    logger.info("%s: %d rows re-made bit for bit (config_hash %s)", m.name, len(rows), m.config_hash)
    if args.backfill:
        check = mf.check_manifest(m, ROOT)
        if len(check.hashes) != 1 or check.status == "ok":
            logger.error("%s: not back-filled (%s)", m.name, check.line())
            return 1
        (old,) = check.hashes
        path = ROOT / m.out / m.csv_name
        settings = {(r["stack"], r["scenario"], float(r["duration"])) for r in mf.raw_rows(path, m.kind)}
        if settings != {(m.stack, m.scenario, float(m.duration))}:
            logger.error("%s: not back-filled: %s holds rows of other settings %s", m.name, path, sorted(settings))
            return 1
        try:
            n = mf.restamp_hash(path, old, m.config_hash) if old else mf.backfill_hash(
                path, m.config_hash, last=m.kind == "interventions")
        except ValueError as err:
            logger.error("%s: not back-filled: %s", m.name, err)
            return 1
        from sofar_agents.evaluation.configs import write_config_json

        write_config_json(ROOT / m.out, [m.config()])
        logger.info("%s: %d rows now carry config_hash %s (before: %s)", m.name, n, m.config_hash, old or "none")
    return 0


if __name__ == "__main__":
    sys.exit(main())
