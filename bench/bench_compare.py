"""Interleaved A/B of env speed: the working tree against a git revision, or two controller settings.

Run through ``python bench/bench_env.py --compare REV [--rounds 5] [other bench_env options]`` or
``python bench/bench_env.py --compare-stack JSON [--rounds 5] [...]``.

With ``--compare REV`` the revision is exported (``git archive``) into a temporary directory (``--new-stack
PRESET``: the working tree's side runs that preset, the revision its default); with ``--compare-stack JSON``
both sides are the working tree, "old" with the controller of ``--stack`` and "new" with the controller
overrides JSON (e.g. ``{"mpc": {"qp_solver": "daqp"}}``). Then ``--rounds``
rounds alternate one timed pass of each side, the order flipping every round (old-new, new-old, ...),
so that a drift of the host's speed (other tenants, thermal state) falls on both sides alike.

Every pass is a fresh subprocess running :mod:`bench_pass` (next to this script) with ``PYTHONPATH``
set to the side's tree. It makes the environment through the public constructor only
(``gymnasium.make`` of the registered ``SOfAR-<Circuit>-v0`` id with keyword arguments that the old
revision accepts too, :func:`env_spec`) and imports nothing else of the package, so a revision from
before any of the package's later modules runs unchanged; the pass checks which ``sofar_env`` it
imported. It times each step with the wall clock and with the process's CPU time
(``time.process_time``), and digests every observation and reward; with ``--vector N`` it also times an
AsyncVectorEnv. The report says whether all passes of both sides drove the same trajectory to the bit.

Reported per side: the median CPU and wall time per step over the rounds (and steps/s) with their
min-max spread; and the ratios new/old of the medians together with the median and range of the
per-round ratios (adjacent passes). On a shared host the CPU time is the figure to compare: other
load stretches the wall time of both sides, not the CPU time a step takes. The per-component
breakdown of a plain ``bench_env.py`` run is not part of the comparison (it instruments internals that
older revisions do not have).
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


def env_spec(args: argparse.Namespace, stack: dict | None = None) -> tuple[str, dict]:
    """The registered id and the ``gymnasium.make`` keyword arguments of a pass for ``bench_env.py``'s options
    ``args``; ``stack`` (a mapping of controller overrides), where given, in place of the preset.

    For the paper world and the default controller only keys that every revision's public constructor accepts
    are set (the circuit's ``SOfAR-<Circuit>-v0`` id, ``rho``, ``n_opponents``, ``timing_info``); ``scenario``
    and ``stack`` are added only where they differ from those defaults (a revision without them fails the pass
    with its own configuration error). ``timing_info`` is given (False) on both sides: its default changed."""
    kwargs: dict = {"rho": args.rho, "n_opponents": args.opponents, "timing_info": False}
    if args.scenario != "paper":
        kwargs["scenario"] = args.scenario
    if stack is not None:
        kwargs["stack"] = stack
    elif args.stack != "sofar":
        kwargs["stack"] = args.stack
    return f"SOfAR-{args.track}-v0", kwargs


def pass_command(env_id: str, kwargs: dict, args: argparse.Namespace, out: Path) -> list[str]:
    """The command line of one pass (:mod:`bench_pass`, next to this script) that writes its JSON to ``out``."""
    cmd = [sys.executable, str(_HERE / "bench_pass.py"), "--env-id", env_id, "--kwargs", json.dumps(kwargs),
           "--steps", str(args.steps), "--gamma", repr(float(args.gamma)), "--seed", str(args.seed),
           "--json", str(out)]
    if args.vector:
        cmd += ["--vector", str(args.vector)]
    return cmd


def run_pass(tree: Path, cmd: list[str], out: Path) -> dict:
    """Run the pass ``cmd`` in a fresh subprocess whose ``PYTHONPATH`` starts with ``tree``; checks that the
    pass imported ``tree``'s ``sofar_env`` and returns its JSON."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(tree)] + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
    proc = subprocess.run(cmd, cwd=str(tree), env=env, capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"benchmark pass in {tree} failed:\n{proc.stderr[-4000:]}")
    with open(out) as fh:
        result = json.load(fh)
    if Path(result["package"]).resolve() != (Path(tree) / "sofar_env").resolve():
        raise RuntimeError(f"the pass meant for {tree} imported sofar_env from {result['package']}")
    return result


def _summary(values: list[float]) -> dict:
    a = np.asarray(values, float)
    return {"median": float(np.median(a)), "min": float(a.min()), "max": float(a.max()),
            "values": [float(v) for v in a]}


def _side_summary(passes: list[dict]) -> dict:
    out = {"cpu_ms_per_step": _summary([p["cpu_ms_per_step"] for p in passes]),
           "wall_ms_per_step": _summary([p["wall_ms_per_step"] for p in passes]),
           "steps_per_s": _summary([p["steps_per_s"] for p in passes]),
           "step_ms_median": _summary([p["step_ms"]["median"] for p in passes]),
           "episodes_ended": [p["episodes_ended"] for p in passes],
           "reference_workload_ms": _summary([p["reference_workload_ms"]["after"] for p in passes]),
           "trajectory_digests": sorted({p.get("trajectory_digest", "") for p in passes})}
    loads = [p["load_average_1min"]["after"] for p in passes]
    if all(v is not None for v in loads):
        out["load_average_1min"] = _summary(loads)
    if all("vector" in p for p in passes):
        out["vector_steps_per_s"] = _summary([p["vector"]["steps_per_s"] for p in passes])
        out["vector_over_single"] = _summary([p["vector"]["steps_per_s"] / p["steps_per_s"] for p in passes])
    return out


def ratios(old: list[dict], new: list[dict]) -> dict:
    """new/old of the CPU and wall time per step, and of the steps/s: of the sides' medians and per round (the
    two passes of a round ran next to each other). Below 1 for the times (above 1 for steps/s): new is faster."""
    def of(key):
        a, b = [p[key] for p in old], [p[key] for p in new]
        return {"of_medians": float(np.median(b) / np.median(a)),
                "per_round": _summary([y / x for x, y in zip(a, b)])}
    return {"cpu_ms_per_step": of("cpu_ms_per_step"), "wall_ms_per_step": of("wall_ms_per_step"),
            "steps_per_s": of("steps_per_s")}


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


def _describe(old: dict, new: dict) -> str:
    return (f"old {old['cpu_ms_per_step']:.3f} ms CPU / {old['wall_ms_per_step']:.3f} ms wall, "
            f"new {new['cpu_ms_per_step']:.3f} / {new['wall_ms_per_step']:.3f} ms per step")


def same_trajectories(old: list[dict], new: list[dict]) -> bool | None:
    """Whether every pass of both sides drove the same trajectory (one :mod:`bench_pass` digest, the same on
    both sides); None where a pass has no digest."""
    digests = [p.get("trajectory_digest") for p in (*old, *new)]
    if not digests or None in digests:
        return None
    return len(set(digests)) == 1


def _finish(args: argparse.Namespace, result: dict, passes: dict[str, list]) -> dict:
    result.update({"ratio": ratios(passes["old"], passes["new"]),
                   "same_trajectories": same_trajectories(passes["old"], passes["new"]),
                   # steps/s new/old, as before the CPU times were recorded
                   "ratio_of_medians": float(np.median([p["steps_per_s"] for p in passes["new"]])
                                             / np.median([p["steps_per_s"] for p in passes["old"]])),
                   "cpu_count": os.cpu_count()})
    _print(result)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(result, fh, indent=2)
    return result


def _header(args: argparse.Namespace) -> dict:
    return {"track": args.track, "scenario": args.scenario, "stack": args.stack, "rho": args.rho,
            "opponents": args.opponents, "gamma": args.gamma, "steps": args.steps, "rounds": args.rounds,
            "seed": args.seed}


def compare_revisions(args: argparse.Namespace) -> dict:
    """Interleaved A/B of the revision ``args.compare`` (old) against the working tree (new), both through the
    public constructor (:func:`env_spec`, :mod:`bench_pass`); prints and returns the result."""
    if args.rounds < 1:
        raise SystemExit("--rounds must be >= 1")
    repo = Path(_git(_HERE, "rev-parse", "--show-toplevel"))
    head = _git(repo, "rev-parse", "HEAD")
    dirty = bool(_git(repo, "status", "--porcelain", "--untracked-files=no"))
    env_id, kwargs = env_spec(args)
    new_kwargs = kwargs if args.new_stack is None else {**kwargs, "stack": args.new_stack}

    def run(side, tree, scratch, r):
        out = scratch / f"pass_{side}_{r}.json"
        return run_pass(tree, pass_command(env_id, kwargs if side == "old" else new_kwargs, args, out), out)

    old_commit, passes = interleave(repo, args.compare, args.rounds, run, _describe)
    result = {**_header(args), "env_id": env_id, "kwargs": kwargs,
              **({"stack": f"{args.new_stack} (new side)"} if args.new_stack else {}),
              "old": {"rev": args.compare, "commit": old_commit, "kwargs": kwargs, **_side_summary(passes["old"])},
              "new": {"rev": "working tree", "commit": head, "dirty": dirty, "kwargs": new_kwargs,
                      **_side_summary(passes["new"])}}
    return _finish(args, result, passes)


def compare_stacks(args: argparse.Namespace, stack: dict) -> dict:
    """Interleaved A/B in the working tree: the controller of ``args.stack`` (old) against the controller
    overrides ``stack`` (new), e.g. ``{"mpc": {"qp_solver": "daqp"}}``; prints and returns the result."""
    if args.rounds < 1:
        raise SystemExit("--rounds must be >= 1")
    repo = Path(_git(_HERE, "rev-parse", "--show-toplevel"))
    specs = {"old": env_spec(args), "new": env_spec(args, stack=stack)}
    results: dict[str, list] = {"old": [], "new": []}
    with tempfile.TemporaryDirectory(prefix="sofar-ab-") as tmp:
        for r in range(args.rounds):
            for side in (("old", "new") if r % 2 == 0 else ("new", "old")):
                out = Path(tmp) / f"pass_{side}_{r}.json"
                results[side].append(run_pass(repo, pass_command(*specs[side], args, out), out))
            print(f"  round {r + 1}/{args.rounds}: {_describe(results['old'][-1], results['new'][-1])}", flush=True)
    head = _git(repo, "rev-parse", "HEAD")
    result = {**_header(args), "env_id": specs["old"][0],
              "old": {"rev": f"stack {args.stack}", "commit": head, "kwargs": specs["old"][1],
                      **_side_summary(results["old"])},
              "new": {"rev": f"stack overrides {json.dumps(stack)}", "commit": head, "kwargs": specs["new"][1],
                      **_side_summary(results["new"])}}
    return _finish(args, result, results)


def _print(res: dict) -> None:
    old, new = res["old"], res["new"]
    print(f"{res['track']} ({res['scenario']} world, stack {res['stack']}), {res['opponents']} opponents at "
          f"rho={res['rho']}, gamma={res['gamma']}, {res['steps']} steps per pass, {res['rounds']} interleaved rounds")
    for name, side in (("old", old), ("new", new)):
        label = f"{side['rev']} ({side['commit'][:9]}{', modified' if side.get('dirty') else ''})"
        print(f"  {name} {label}: {side['cpu_ms_per_step']['median']:.3f} ms CPU per step median "
              f"[{side['cpu_ms_per_step']['min']:.3f}, {side['cpu_ms_per_step']['max']:.3f}], "
              f"{side['wall_ms_per_step']['median']:.3f} ms wall [{side['wall_ms_per_step']['min']:.3f}, "
              f"{side['wall_ms_per_step']['max']:.3f}] ({side['steps_per_s']['median']:.0f} env steps/s)")
    if old.get("kwargs") != new.get("kwargs"):
        print(f"  make kwargs: old {json.dumps(old.get('kwargs'))}, new {json.dumps(new.get('kwargs'))}")
    same = res.get("same_trajectories")
    print("  trajectories: " + {True: "identical to the bit on both sides in every pass (observations and rewards)",
                                False: "differ (observations or rewards of some pass; or another observation layout)",
                                None: "not compared (a pass without a digest)"}[same])
    for key, what in (("cpu_ms_per_step", "CPU time per step"), ("wall_ms_per_step", "wall time per step")):
        r = res["ratio"][key]
        pr = r["per_round"]
        print(f"  {what} new/old: {r['of_medians']:.3f} of the medians; per round median {pr['median']:.3f} "
              f"[{pr['min']:.3f}, {pr['max']:.3f}]")
    if "load_average_1min" in old and "load_average_1min" in new:
        print(f"  host: 1-min load average {old['load_average_1min']['min']:.1f}-{old['load_average_1min']['max']:.1f} "
              f"(old passes), {new['load_average_1min']['min']:.1f}-{new['load_average_1min']['max']:.1f} (new) "
              f"on {res['cpu_count']} CPUs; reference workload median {old['reference_workload_ms']['median']:.1f} / "
              f"{new['reference_workload_ms']['median']:.1f} ms")
    if "vector_steps_per_s" in old and "vector_steps_per_s" in new:
        for side in ("old", "new"):
            v = res[side]
            print(f"  AsyncVectorEnv ({side}): {v['vector_steps_per_s']['median']:.0f} env steps/s median "
                  f"[{v['vector_steps_per_s']['min']:.0f}, {v['vector_steps_per_s']['max']:.0f}], "
                  f"{v['vector_over_single']['median']:.2f}x one process")
