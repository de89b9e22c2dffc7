"""Time what a new user does in the first ten minutes, on this machine, and write the table.

    python eval/first_ten_minutes.py                      # -> results/first_ten_minutes.md, README.md's copy
    python eval/first_ten_minutes.py --no-ray --no-readme

Runs each step of the README's "The first ten minutes" as its own process, from the repository root, with
its outputs in a temporary folder, and times it (wall clock): the demo on a fresh install (empty numba and
CasADi caches, so the per-step kernels and the MPC's C code are compiled) and again, the README's
one-episode snippet, the quick table (the process pool, and Ray), the quick training run and its learning
curves, and the ahead-of-time compilation of every world (``python -m sofar_env.compile``, fresh caches).
The Markdown table, with the machine it ran on (CPU, cores, memory, load), goes to ``--out``; the README
holds a copy of it between the ``first-ten-minutes`` markers, which this script rewrites, and the
documentation site and the scripts' help refer to the file. Takes about five minutes on 2 cores.
"""

from __future__ import annotations

import argparse
import datetime
import logging
import os
import platform
import re
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from sofar_agents.evaluation.files import write_text_atomic

ROOT = Path(__file__).resolve().parents[1]
logger = logging.getLogger("first_ten_minutes")

BEGIN, END = "<!-- first-ten-minutes: begin -->", "<!-- first-ten-minutes: end -->"
"""The markers of the README's copy of the table."""

SNIPPET = '''import gymnasium as gym
import numpy as np
import sofar_env  # registers the ids

env = gym.make("SOfAR-LagunaSeca-v0", rho=0.3)          # 200 s race, 4 opponents
obs, info = env.reset(seed=0)
done = False
while not done:
    obs, reward, terminated, truncated, info = env.step(np.array([0.5], np.float32))
    done = terminated or truncated
print(f"{info['sim_time']:.0f} s, overtakes {info['overtakes']}, success {info['is_success']}")
'''
"""The README's one-episode snippet (step 3), run as it is written there."""


@dataclass
class Step:
    number: str
    what: str
    command: str
    """As a user types it (the table's command column)."""
    argv: list[str]
    fresh_caches: bool = False
    """Run with empty numba and CasADi caches: a fresh install."""
    seconds: float | None = None
    output: str = ""


def steps(tmp: Path, ray: bool) -> list[Step]:
    py = sys.executable
    out = [
        Step("2", "watch a race, first run after installing (compiles the per-step kernels and the MPC's C code, "
             "once)", "`python -m sofar_env.demo` (60 s race, GIF, summary)",
             [py, "-m", "sofar_env.demo", "--no-progress", "--out", str(tmp / "first.gif")], fresh_caches=True),
        Step("2", "watch a race (every later run)", "`python -m sofar_env.demo`",
             [py, "-m", "sofar_env.demo", "--no-progress", "--out", str(tmp / "sofar_demo.gif")]),
        Step("3", "one episode at a fixed gamma", "the README's one-episode snippet (a full 200 s race, 2000 "
             "control steps)",
             [py, "-c", SNIPPET]),
        Step("4", "a quick table", "`python eval/table.py --quick` (2 circuits, 1 episode of 30 s per strategy, "
             "a worker per core)", [py, "eval/table.py", "--quick", "--no-progress", "--out", str(tmp / "quick")]),
    ]
    if ray:
        out.append(Step("4", "the same on Ray (a private local instance, started for this run)",
                        "`python eval/table.py --quick --backend ray --workers 2`",
                        [py, "eval/table.py", "--quick", "--no-progress", "--backend", "ray", "--workers", "2",
                         "--out", str(tmp / "quick_ray")]))
    out += [
        Step("5", "a quick training run", "`python train/pasta.py --quick` (16384 steps, 30 s episodes, "
             "`runs/pasta_quick`)", [py, "train/pasta.py", "--quick", "--no-progress", "--out", str(tmp / "pasta")]),
        Step("6", "its learning curves", "`python eval/plot_training.py runs/pasta_quick` (PNG next to the logs)",
             [py, "eval/plot_training.py", str(tmp / "pasta")]),
        Step("-", "compile every world ahead of time (CI, cluster nodes; fresh caches)",
             "`python -m sofar_env.compile`", [py, "-m", "sofar_env.compile"], fresh_caches=True),
    ]
    return out


def run(step: Step, tmp: Path) -> None:
    env = dict(os.environ, MPLBACKEND="Agg")
    if step.fresh_caches:
        caches = Path(tempfile.mkdtemp(prefix="caches_", dir=tmp))
        env.update(NUMBA_CACHE_DIR=str(caches / "numba"), SOFAR_CACHE_DIR=str(caches / "sofar"))
    logger.info("step %s: %s", step.number, step.command)
    t0 = time.perf_counter()
    proc = subprocess.run(step.argv, cwd=ROOT, env=env, capture_output=True, text=True)
    step.seconds = time.perf_counter() - t0
    step.output = proc.stdout + proc.stderr
    if proc.returncode != 0:
        raise RuntimeError(f"{step.command} failed ({proc.returncode}):\n{step.output[-3000:]}")
    logger.info("  %.1f s", step.seconds)


def machine() -> dict[str, str]:
    """What the numbers were measured on."""
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    try:
        usable = len(os.sched_getaffinity(0))
    except AttributeError:
        usable = os.cpu_count() or 1
    memory = ""
    try:
        kb = int(re.search(r"MemTotal:\s+(\d+)", Path("/proc/meminfo").read_text()).group(1))
        memory = f", {kb / 2**20:.0f} GiB memory"
    except (OSError, AttributeError):
        pass
    return {"cpu": cpu, "cores": f"{usable} of {os.cpu_count()} cores usable{memory}",
            "python": platform.python_version(), "system": f"{platform.system()} {platform.release()}"}


def load() -> str:
    try:
        return ", ".join(f"{x:.1f}" for x in os.getloadavg())
    except OSError:
        return "n/a"


def _seconds(s: float) -> str:
    return f"{s:.0f} s" if s < 120 else f"{s / 60:.1f} min"


def render(rows: list[Step], info: dict[str, str], loads: tuple[str, str], snippet_line: str, when: str,
           ray_ratio: float | None) -> str:
    """The Markdown of ``results/first_ten_minutes.md``."""
    lines = [
        "| # | step | command | wall time |",
        "|---|---|---|---|",
        "| 1 | install | `pip install torch==2.13.0 && pip install -e \".[dev]\"` | not timed (depends on the "
        "network and the package index) |",
    ]
    for s in rows:
        lines.append(f"| {s.number} | {s.what} | {s.command} | {_seconds(s.seconds)} |")
    notes = [
        "",
        f"Measured by `python eval/first_ten_minutes.py` on {when}: {info['cpu']}, {info['cores']}, Python "
        f"{info['python']}, {info['system']}; load average (1, 5, 15 min) {loads[0]} before and {loads[1]} after "
        "(other jobs shared the machine: the times are on the slow side). Each step ran as its own process from "
        "the repository root.",
        "",
        f"Step 3 printed `{snippet_line}`. The first run after installing compiles the per-step kernels and the "
        "MPC's C code and caches them on disk; every later process loads them (`python -m sofar_env.compile` does "
        "it ahead of time, for all worlds).",
    ]
    if ray_ratio is not None:
        notes += ["", f"On Ray the quick table took {ray_ratio:.1f}x the time of the local process pool. Ray first "
                  "starts an instance and its workers (seconds), a cost that small sweeps feel most and that long "
                  "sweeps or a cluster pay once."]
    return "\n".join(lines + notes) + "\n"


def update_readme(readme: str, table: str) -> str:
    """``readme`` with the text between the markers replaced by ``table``."""
    start, end = readme.index(BEGIN) + len(BEGIN), readme.index(END)
    return readme[:start] + "\n" + table + readme[end:]


def main(argv: list[str] | None = None) -> Path:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", default="results/first_ten_minutes.md", help="Markdown table to write")
    p.add_argument("--no-ray", action="store_true", help="leave out the quick table on Ray")
    p.add_argument("--no-readme", action="store_true", help="do not update the README's copy of the table")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    ray = not args.no_ray
    if ray:
        try:
            import ray as _ray  # noqa: F401
        except ImportError:
            ray = False
    before = load()
    with tempfile.TemporaryDirectory(prefix="first_ten_minutes_") as tmp:
        rows = steps(Path(tmp), ray)
        for step in rows:
            run(step, Path(tmp))
    after = load()
    snippet = next(s for s in rows if s.number == "3").output.strip().splitlines()[-1]
    tables = [s for s in rows if s.number == "4"]
    ratio = tables[1].seconds / tables[0].seconds if len(tables) == 2 else None
    when = datetime.date.today().isoformat()
    table = render(rows, machine(), (before, after), snippet, when, ratio)
    out = ROOT / args.out
    write_text_atomic(out, "# The first ten minutes\n\n" + table)
    logger.info("wrote %s", out)
    if not args.no_readme:
        readme = ROOT / "README.md"
        write_text_atomic(readme, update_readme(readme.read_text(encoding="utf-8"), table))
        logger.info("updated the table in %s", readme)
    return out


if __name__ == "__main__":
    main()
