"""eval/parked_cars.py: races a parked field and reports one row per run."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def test_parked_cars_reports_a_row_per_run():
    proc = subprocess.run([sys.executable, str(ROOT / "eval" / "parked_cars.py"), "--tracks", "Monza",
                           "--seeds", "0", "1", "--duration", "4"], check=True, capture_output=True, text=True,
                          timeout=300)
    rows = [line for line in proc.stdout.splitlines() if line.startswith("| Monza |")]
    assert len(rows) == 2
    cells = [c.strip() for c in rows[1].strip("|").split("|")]
    assert cells[:3] == ["Monza", "1", "ok"] and float(cells[3]) == pytest.approx(4.0)
    assert float(cells[4]) > 50.0  # driven [m] in 4 s
    assert "2 runs: 2 ok; 0 with a standstill of 5 s or more" in proc.stdout


@pytest.mark.parametrize("args,words", [(["--duration", "0"], "argument --duration: must be a number > 0"),
                                        (["--gamma", "2"], "argument --gamma: must lie in"),
                                        (["--stack", "sofar-99"], "argument --stack: invalid choice")])
def test_parked_cars_refuses_bad_options(args, words):
    proc = subprocess.run([sys.executable, str(ROOT / "eval" / "parked_cars.py"), *args],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and words in proc.stderr
