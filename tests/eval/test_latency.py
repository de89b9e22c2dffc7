"""eval/latency.py: statistics and the JSON report of a short closed loop."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from sofar_agents import evaluation as ev

ROOT = Path(__file__).resolve().parents[2]
STAT_KEYS = {"mean", "std", "median", "p95"}


def test_latency_stats_hand_computed():
    s = ev.latency_stats([1.0, 2.0, 3.0, 4.0])
    assert s["mean"] == pytest.approx(2.5)
    assert s["std"] == pytest.approx(np.std([1, 2, 3, 4]))
    assert s["median"] == pytest.approx(2.5)
    assert s["p95"] == pytest.approx(3.85)
    assert s["n"] == 4
    empty = ev.latency_stats([])
    assert empty["n"] == 0 and math.isnan(empty["mean"])


def test_format_latency_next_to_the_paper():
    s = {"mean": 3.2, "std": 0.5, "median": 3.0, "p95": 4.0, "n": 10}
    md = ev.format_latency({"mpc_ms": s, "rl_ms": dict(s, mean=0.41), "rl_source": "policy x",
                            "machine": {"cpu": "CPU X", "cores": 2}})
    lines = md.splitlines()
    assert lines[2] == "| MPC | 3.200 ± 0.500 | 3.000 | 4.000 | 10 | 1.60 ± 0.34 | 2.00 |"
    assert lines[3].startswith("| RL (policy x) | 0.410") and lines[3].endswith("| 0.82 ± 0.12 | 0.50 |")
    assert not any(line.startswith("| MIQP") for line in lines)  # not measured: no row
    assert lines[-1].startswith("This machine: CPU X, 2 cores.")


def test_latency_json_report(tmp_path):
    out = tmp_path / "latency.json"
    proc = subprocess.run([sys.executable, str(ROOT / "eval" / "latency.py"), "--seconds", "3", "--json", str(out)],
                          capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-3000:]
    report = json.loads(out.read_text())
    for key in ("mpc_ms", "miqp_ms", "rl_ms", "controller_step_ms"):
        assert STAT_KEYS <= set(report[key]), key
    assert report["mpc_ms"]["n"] == report["setup"]["control_steps"] >= 30
    assert 0.0 < report["mpc_ms"]["mean"] < 1000.0 and report["mpc_ms"]["p95"] >= report["mpc_ms"]["median"]
    assert 0 < report["miqp_ms"]["n"] <= report["mpc_ms"]["n"]  # only the steps where the MIQP ran
    assert report["rl_ms"]["n"] > 0 and report["rl_ms"]["mean"] > 0.0
    assert report["controller_step_ms"]["mean"] >= report["mpc_ms"]["mean"]
    assert report["machine"]["cores"] >= 1 and "cpu" in report["machine"]
    # the solver versions are recorded (read from the installed distributions)
    assert report["machine"]["piqp"] and report["machine"]["daqp"]
    assert report["paper_ms"]["mpc_ms"]["mean"] == 1.60
    assert "| MPC |" in proc.stdout and "1.60 ± 0.34" in proc.stdout
