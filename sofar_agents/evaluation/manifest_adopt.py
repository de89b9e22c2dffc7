"""A default's table started from a candidate's rows: :func:`adopt_rows`.

When the default controller moves to a candidate preset, the candidate has usually run the same episodes already (its
``candidate_*`` manifests: the same seeds, the same configuration, another preset name). Its rows are then the new
default's rows: the configuration hash is that of the resolved configuration, not of the name, so the episodes would be
re-made bit for bit. :func:`adopt_rows` copies its fixed-gamma rows into the default manifest's CSV, with the ``stack``
column relabelled to the target manifest's preset and every other byte as it was, and writes a run record there that
names the candidate's run. Rows of a policy (Adaptive, self-play: a ``policy_id``) are never adopted: the policy is not
part of the configuration hash, and a moved default trains its policies again. ``python eval/manifest.py run TARGET``
then resumes from those rows and runs only what the candidate did not (the Adaptive rows, a policy of the new default),
listing the candidate's run under ``earlier_runs``. ``python eval/manifest.py verify TARGET`` re-makes some of them to
show the claim. The same holds for a second policy's Pareto front on the seeds of a first: its fixed-gamma rows are the
first front's. Nothing is written unless every check passes.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from sofar_agents.evaluation.files import write_json_atomic, write_text_atomic
from sofar_agents.evaluation.manifest import (Manifest, episode_ids, raw_rows, record_path, row_episode,
                                              row_id)

__all__ = ["ADOPTABLE_KINDS", "adopt_rows"]

ADOPTABLE_KINDS = ("table1", "table2", "multi-agent", "pareto")
"""Kinds whose CSV rows are whole episodes (races) that a manifest of the same configuration would re-make (a pareto
manifest: its fixed gammas, when another policy's front is judged on the episodes of one that ran them)."""


def adopt_rows(target: Manifest, source: Manifest, root: str | os.PathLike) -> int:
    """Copy the fixed-gamma rows of ``source``'s CSV (no ``policy_id``) that are episodes of ``target`` into
    ``target``'s CSV (under ``root``) and return how many. The two must be of one kind in :data:`ADOPTABLE_KINDS` and
    resolve to one configuration hash, every adopted row must carry that hash and run ``target``'s scenario and
    duration, and none of their episodes may be in ``target``'s CSV already; else ``ValueError`` naming what differs,
    and no file is written. The rows keep their bytes but for the ``stack`` field (``target.stack``); they go after
    the rows the CSV has (or into a new CSV with ``source``'s header, which an existing CSV must share). ``target``'s
    run record (:func:`~.manifest.record_path`) gets ``source``'s run (commit, wall time, end) as an earlier run,
    with ``adopted_from`` naming it, unless it has a record of its own already."""
    root = Path(root)
    if target.kind != source.kind or target.kind not in ADOPTABLE_KINDS:
        raise ValueError(f"rows are adopted between two manifests of one kind of {', '.join(ADOPTABLE_KINDS)}; "
                         f"{source.name} is {source.kind!r}, {target.name} {target.kind!r}")
    if target.config_hash != source.config_hash:
        raise ValueError(f"{source.name} resolves to config_hash {source.config_hash}, {target.name} to "
                         f"{target.config_hash}: another configuration, whose rows {target.name} would not re-make")
    src_path = root / source.out / source.csv_name
    if not src_path.is_file():
        raise ValueError(f"{source.name}: no rows at {src_path}; run it first")
    wanted = episode_ids(target, root)
    rows = [r for r in raw_rows(src_path, source.kind) if row_episode(target, r) in wanted and not r["policy_id"]]
    if not rows:
        raise ValueError(f"none of the fixed-gamma rows of {src_path} is an episode of {target.name}")
    for r in rows:
        if r["config_hash"] != target.config_hash:
            raise ValueError(f"{src_path}: row {row_id(target, r)} carries config_hash {r['config_hash'] or 'none'}, "
                             f"not {target.config_hash}")
        if r["scenario"] != target.scenario or float(r["duration"]) != float(target.duration):
            raise ValueError(f"{src_path}: row {row_id(target, r)} ran scenario {r['scenario']!r} for "
                             f"{r['duration']} s, {target.name} {target.scenario!r} for {target.duration} s")
    keys = {row_id(target, r) for r in rows}
    lines, header = _source_lines(src_path, keys, target)
    dst_path = root / target.out / target.csv_name
    if dst_path.is_file():
        existing = dst_path.read_bytes().decode("utf-8")
        if existing.splitlines()[0] != header.rstrip("\r\n"):
            raise ValueError(f"{dst_path} has another header than {src_path}; not merged")
        present = keys & {row_id(target, r) for r in raw_rows(dst_path, target.kind)}
        if present:
            raise ValueError(f"{dst_path} holds {len(present)} of these episodes already, e.g. {sorted(present)[0]}")
        text = existing + ("" if existing.endswith("\n") else "\n") + "".join(lines)
    else:
        text = header + "".join(lines)
    record = record_path(target, dst_path.parent)
    dst_path.parent.mkdir(parents=True, exist_ok=True)
    write_text_atomic(dst_path, text)
    if not record.is_file():
        write_json_atomic(record, _adopted_record(target, source, root), indent=1, sort_keys=True)
    return len(lines)


def _source_lines(path: Path, keys: set, target: Manifest) -> tuple[list[str], str]:
    """The lines of the CSV ``path`` whose rows :func:`~.manifest.row_id` names in ``keys``, with the ``stack``
    field set to ``target.stack`` (the lines as written: no quoting, every other byte kept), and the header line."""
    data = path.read_bytes().decode("utf-8")
    if '"' in data:
        raise ValueError(f"{path}: quoted values; not copied")
    header, *body = data.splitlines(keepends=True)
    names = header.rstrip("\r\n").split(",")
    if "stack" not in names:
        raise ValueError(f"{path}: no stack column")
    at, out = names.index("stack"), []
    for line in body:
        text = line.rstrip("\r\n")
        fields = text.split(",")
        if len(fields) != len(names):
            raise ValueError(f"{path}: a line of {len(fields)} fields under a header of {len(names)}")
        if row_id(target, dict(zip(names, fields))) in keys:
            fields[at] = target.stack
            out.append(",".join(fields) + (line[len(text):] or "\n"))
    return out, header if header.endswith("\n") else header + "\n"


def _adopted_record(target: Manifest, source: Manifest, root: Path) -> dict:
    """A run record for ``target`` whose only run is ``source``'s (as :func:`~.manifest.run_manifest`'s
    ``earlier_runs`` lists runs); the source's record when it has one."""
    try:
        old = json.loads(record_path(source, root / source.out).read_text())
    except (OSError, ValueError):
        old = {}
    run = {k: old.get(k) for k in ("commit", "wall_time_s", "finished_at")}
    runs = [r for r in old.get("earlier_runs", []) if isinstance(r, dict)] if isinstance(old, dict) else []
    return {"manifest": target.name, "config_hash": [target.config_hash], "commit": run["commit"],
            "wall_time_s": run["wall_time_s"], "finished_at": run["finished_at"], "adopted_from": source.name,
            "earlier_runs": runs}
