"""eval/table.py end to end: the quick Table I completes, and a rerun resumes from the CSV."""

from __future__ import annotations

import csv
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
TABLE = ROOT / "eval" / "table.py"


def _read(path: Path) -> list[dict]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def _run_quick(out: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(TABLE), "--quick", "--out", str(out), "--workers", "2",
                           "--no-progress"], capture_output=True, text=True, timeout=170, cwd=ROOT)


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("quick")
    return out, _run_quick(out)


def test_quick_table_completes_with_every_row(quick_run):
    out, proc = quick_run
    assert proc.returncode == 0, proc.stderr[-3000:]
    rows = _read(out / "table1_episodes.csv")
    strategies = sorted({r["strategy"] for r in rows})
    assert len(strategies) == 2 and "gamma=0.50" in strategies
    assert sorted((r["track"], r["strategy"]) for r in rows) == sorted(
        (t, s) for t in ("LagunaSeca", "Monza") for s in strategies)
    for r in rows:
        assert float(r["sim_time"]) > 0 and int(r["steps"]) > 0 and r["success"] in ("0", "1")
        assert 0.05 <= float(r["mean_gamma"]) <= 1.0
        if r["success"] == "1":
            assert float(r["sim_time"]) == pytest.approx(30.0, abs=0.051)  # the --quick horizon
    # every rho/seed pair is shared by both strategies
    assert len({(r["track"], r["seed"]) for r in rows}) == 2
    md = (out / "table1.md").read_text()
    assert "Table I" in proc.stdout
    assert "LagunaSeca (LS)" in md and "Monza" in md and "All circuits" in md and "γ = 0.50" in md
    main_table = md.split("## Success rate")[0]
    assert main_table.count("| γ = 0.50 |") == 3  # Laguna Seca, Monza, all circuits


def test_quick_table_resumes(quick_run):
    out, proc = quick_run
    assert proc.returncode == 0, proc.stderr[-3000:]
    csv_path = out / "table1_episodes.csv"
    before = _read(csv_path)
    again = _run_quick(out)
    assert again.returncode == 0, again.stderr[-3000:]
    assert _read(csv_path) == before  # nothing re-run
    assert "taken from the CSV, none run" in again.stdout
    # drop one episode: exactly that one is run again
    lines = csv_path.read_text().splitlines(keepends=True)
    dropped = before[1]
    csv_path.write_text("".join(lines[:2] + lines[3:]))
    third = _run_quick(out)
    assert third.returncode == 0, third.stderr[-3000:]
    after = _read(csv_path)
    assert len(after) == len(before)
    key = ("track", "strategy", "rho", "seed")
    kept = [tuple(r[k] for k in key) for r in before if r is not dropped]
    assert [tuple(r[k] for k in key) for r in after[:-1]] == kept
    assert tuple(after[-1][k] for k in key) == tuple(dropped[k] for k in key)
    assert after[-1]["sim_time"] == dropped["sim_time"] and after[-1]["overtakes"] == dropped["overtakes"]
