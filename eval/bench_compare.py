"""Interleaved A/B of env throughput: the working tree against a git revision.

Run through ``python eval/bench_env.py --compare REV [--rounds 5] [other bench_env options]``.

The revision ``REV`` is exported (``git archive``) into a temporary directory. Then
``--rounds`` rounds alternate one timed pass of each side, the order flipping every round
(old-new, new-old, ...), so that a drift of the host's speed (other tenants, thermal
state) falls on both sides alike. Every pass is a fresh subprocess running this
directory's ``bench_env.py`` (``--repeats 1``) with ``PYTHONPATH`` set to the side's tree,
so the only difference between the sides is the ``sofar_env`` package that is imported.
Each pass also records the per-component breakdown (unless ``--no-breakdown``) and,
with ``--vector N``, the AsyncVectorEnv throughput.

Reported per side: the median steps/s over the rounds, the min-max spread, the median
breakdown per component; and the ratio new/old of the medians together with the
median and range of the per-round ratios (adjacent passes).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path

import numpy as np

_HERE = Path(__file__).resolve().parent
# options of bench_env.py that belong to the comparison, not to the passes (name -> takes a value)
_OWN_OPTIONS = {"--compare": True, "--rounds": True, "--json": True, "--repeats": True}


def _git(repo: Path, *args: str) -> str:
    return subprocess.run(["git", "-C", str(repo), *args], check=True, capture_output=True,
                          text=True).stdout.strip()


def export_revision(repo: Path, rev: str, dest: Path) -> str:
    """Export the tree of ``rev`` into ``dest`` (``git archive``); returns the full commit hash."""
    commit = _git(repo, "rev-parse", "--verify", f"{rev}^{{commit}}")
    archive = dest / "rev.tar"
    with open(archive, "wb") as fh:
        subprocess.run(["git", "-C", str(repo), "archive", "--format=tar", commit], check=True, stdout=fh)
    with tarfile.open(archive) as tar:
        tar.extractall(dest / "tree", filter="data")
    archive.unlink()
    return commit


def pass_arguments(argv: list[str]) -> list[str]:
    """``argv`` without the options that belong to the comparison (both ``--opt v`` and ``--opt=v``)."""
    out, skip = [], False
    for arg in argv:
        if skip:
            skip = False
            continue
        name = arg.split("=", 1)[0]
        if name in _OWN_OPTIONS:
            skip = _OWN_OPTIONS[name] and "=" not in arg
            continue
        out.append(arg)
    return out


def run_pass(tree: Path, args: list[str], scratch: Path) -> dict:
    """One timed pass of ``bench_env.py`` with the package of ``tree``, in a fresh subprocess."""
    out = scratch / "pass.json"
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(tree)] + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
    cmd = [sys.executable, str(_HERE / "bench_env.py"), *args, "--repeats", "1", "--json", str(out)]
    proc = subprocess.run(cmd, cwd=str(tree), env=env, capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"benchmark pass in {tree} failed:\n{proc.stderr[-4000:]}")
    with open(out) as fh:
        return json.load(fh)


def _summary(values: list[float]) -> dict:
    a = np.asarray(values, float)
    return {"median": float(np.median(a)), "min": float(a.min()), "max": float(a.max()),
            "values": [float(v) for v in a]}


def _side_summary(passes: list[dict]) -> dict:
    out = {"steps_per_s": _summary([p["steps_per_s"] for p in passes]),
           "step_ms_median": _summary([p["step_ms"]["median"] for p in passes]),
           "reference_workload_ms": _summary([p["reference_workload_ms"]["after"] for p in passes])}
    loads = [p["load_average_1min"]["after"] for p in passes]
    if all(v is not None for v in loads):
        out["load_average_1min"] = _summary(loads)
    names = []
    for p in passes:
        names += [n for n in p.get("breakdown_ms_per_step", {}) if n not in names]
    if names:
        out["breakdown_ms_per_step"] = {n: float(np.median([p["breakdown_ms_per_step"].get(n, 0.0) for p in passes]))
                                        for n in names}
        out["instrumented_ms_per_step"] = float(np.median([p["instrumented_ms_per_step"] for p in passes]))
    kernels = [n for n in passes[0].get("compiled_ms_per_step", {})]
    if kernels:
        out["compiled_ms_per_step"] = {n: float(np.median([p["compiled_ms_per_step"][n] for p in passes]))
                                       for n in kernels}
    if all("vector" in p for p in passes):
        out["vector_steps_per_s"] = _summary([p["vector"]["steps_per_s"] for p in passes])
        out["vector_over_single"] = _summary([p["vector"]["steps_per_s"] / p["steps_per_s"] for p in passes])
    return out


def interleave(repo: Path, rev: str, rounds: int, run, describe) -> tuple[str, dict[str, list]]:
    """Export ``rev`` of ``repo`` and run ``rounds`` rounds of ``run(side, tree, scratch, round)`` for the
    sides "old" (the revision) and "new" (the working tree), the order flipping every round; prints
    ``describe(old_result, new_result)`` per round. Returns the revision's commit and the results per side."""
    results: dict[str, list] = {"old": [], "new": []}
    with tempfile.TemporaryDirectory(prefix="sofar-ab-") as tmp:
        scratch = Path(tmp)
        commit = export_revision(repo, rev, scratch)
        trees = {"old": scratch / "tree", "new": repo}
        for r in range(rounds):
            for side in (("old", "new") if r % 2 == 0 else ("new", "old")):
                results[side].append(run(side, trees[side], scratch, r))
            print(f"  round {r + 1}/{rounds}: {describe(results['old'][-1], results['new'][-1])}", flush=True)
    return commit, results


def compare_revisions(args: argparse.Namespace, argv: list[str]) -> dict:
    """Interleaved A/B of ``args.compare`` (old) against the working tree (new); prints and returns the result."""
    if args.rounds < 1:
        raise SystemExit("--rounds must be >= 1")
    repo = Path(_git(_HERE, "rev-parse", "--show-toplevel"))
    head = _git(repo, "rev-parse", "HEAD")
    dirty = bool(_git(repo, "status", "--porcelain", "--untracked-files=no"))
    child = pass_arguments(argv)
    old_commit, passes = interleave(repo, args.compare, args.rounds,
                                    lambda side, tree, scratch, r: run_pass(tree, child, scratch),
                                    lambda old, new: f"old {old['steps_per_s']:.0f}, new {new['steps_per_s']:.0f} "
                                                     "env steps/s")
    ratios = [n["steps_per_s"] / o["steps_per_s"] for o, n in zip(passes["old"], passes["new"])]
    result = {
        "track": args.track, "scenario": args.scenario, "rho": args.rho, "opponents": args.opponents,
        "gamma": args.gamma, "steps": args.steps, "rounds": args.rounds, "seed": args.seed,
        "old": {"rev": args.compare, "commit": old_commit, **_side_summary(passes["old"])},
        "new": {"rev": "working tree", "commit": head, "dirty": dirty, **_side_summary(passes["new"])},
        "ratio_of_medians": float(np.median([p["steps_per_s"] for p in passes["new"]])
                                  / np.median([p["steps_per_s"] for p in passes["old"]])),
        "ratio_per_round": _summary(ratios),
        "ratio_of_best": float(max(p["steps_per_s"] for p in passes["new"])
                               / max(p["steps_per_s"] for p in passes["old"])),
        "cpu_count": os.cpu_count(),
    }
    _print(result)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(result, fh, indent=2)
    return result


def _print(res: dict) -> None:
    old, new = res["old"], res["new"]
    print(f"{res['track']} ({res['scenario']} world), {res['opponents']} opponents at rho={res['rho']}, "
          f"gamma={res['gamma']}, {res['steps']} steps per pass, {res['rounds']} interleaved rounds")
    print(f"  old {old['rev']} ({old['commit'][:9]}): {old['steps_per_s']['median']:.0f} env steps/s median "
          f"[{old['steps_per_s']['min']:.0f}, {old['steps_per_s']['max']:.0f}]")
    print(f"  new working tree ({new['commit'][:9]}{', modified' if new['dirty'] else ''}): "
          f"{new['steps_per_s']['median']:.0f} env steps/s median "
          f"[{new['steps_per_s']['min']:.0f}, {new['steps_per_s']['max']:.0f}]")
    rr = res["ratio_per_round"]
    print(f"  ratio new/old: {res['ratio_of_medians']:.2f}x of the medians; per round median {rr['median']:.2f}x "
          f"[{rr['min']:.2f}, {rr['max']:.2f}]; best passes {res['ratio_of_best']:.2f}x")
    if "load_average_1min" in old:
        print(f"  host: 1-min load average {old['load_average_1min']['min']:.1f}-{old['load_average_1min']['max']:.1f} "
              f"(old passes), {new['load_average_1min']['min']:.1f}-{new['load_average_1min']['max']:.1f} (new) "
              f"on {res['cpu_count']} CPUs; reference workload median {old['reference_workload_ms']['median']:.1f} / "
              f"{new['reference_workload_ms']['median']:.1f} ms")
    if "breakdown_ms_per_step" in old and "breakdown_ms_per_step" in new:
        print(f"  per-step breakdown, ms (medians of the instrumented passes: old "
              f"{old['instrumented_ms_per_step']:.3f}, new {new['instrumented_ms_per_step']:.3f}):")
        for name in old["breakdown_ms_per_step"]:
            a, b = old["breakdown_ms_per_step"][name], new["breakdown_ms_per_step"].get(name, 0.0)
            print(f"    {name:40s} {a:6.3f} -> {b:6.3f}")
        if "compiled_ms_per_step" in old and "compiled_ms_per_step" in new:
            print("  of which compiled kernels, ms per step:")
            for name, a in old["compiled_ms_per_step"].items():
                print(f"    {name:40s} {a:6.3f} -> {new['compiled_ms_per_step'].get(name, 0.0):6.3f}")
    if "vector_steps_per_s" in old:
        for side in ("old", "new"):
            v = res[side]
            print(f"  AsyncVectorEnv ({side}): {v['vector_steps_per_s']['median']:.0f} env steps/s median "
                  f"[{v['vector_steps_per_s']['min']:.0f}, {v['vector_steps_per_s']['max']:.0f}], "
                  f"{v['vector_over_single']['median']:.2f}x one process")
