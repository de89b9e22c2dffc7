"""Writing hand-built episode rows as a per-episode CSV of ``eval/table.py`` (shared by the script tests)."""

from __future__ import annotations

import csv
from pathlib import Path

from sofar_agents import evaluation as ev

_DEFAULTS = {"sim_time": 200.0, "laps": 1.0, "overtakes": 3, "collision": 0, "off_track": 0, "slack_steps": 0,
             "steps": 2000, "mean_gamma": 0.5, "mpc_failures": 0, "miqp_failures": 0, "wall_time": 1.0,
             "episode": 0, "duration": 200.0, "policy_id": "", "stack": "sofar", "n_opponents": "",
             "scenario": "paper", "stalled": 0}


def write_episode_csv(path: Path, rows) -> None:
    """``rows`` (dicts with at least track, rho, seed, strategy, success, use_miqp) to ``path``, other columns
    at plausible defaults."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=ev.EPISODE_COLUMNS)
        w.writeheader()
        for r in rows:
            w.writerow({**_DEFAULTS, **{k: int(v) if isinstance(v, bool) else v for k, v in r.items()}})


FIRST_FORMAT = """track,strategy,rho,seed,success,sim_time,laps,overtakes,collision,off_track,slack_steps,steps,\
mean_gamma,mpc_failures,miqp_failures,wall_time,episode,use_miqp,duration,policy_id
Indianapolis,adaptive,0.1,547565627,1,200,2.07752,68,0,0,0,2000,0.626424,0,0,7.43006,1,1,200,3ba9d76272
Indianapolis,gamma=0.05,0.1,1454761822,1,200,2.03478,67,0,0,7,2000,0.05,0,0,7.57868,0,1,200,
"""
"""Rows of the first CSV format (the former ``seed13/``, ``seed14/`` files, before they were re-made)."""
