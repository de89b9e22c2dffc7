"""Build a circuit from a centerline CSV and race on it.

    python examples/custom_track.py

A synthetic oval-ish circuit is written to a temporary folder as ``x_m,y_m,w_tr_right_m,w_tr_left_m``,
built with ``python -m sofar_env.tracks build`` and raced through the ``SOfAR-Custom-v0`` id by folder path
(a :class:`sofar_env.tracks.Track` works too: ``track=Track.load(out)``).
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from pathlib import Path

import gymnasium as gym
import numpy as np

import sofar_env  # noqa: F401  (registers the SOfAR ids)

# SOFAR_EXAMPLE_STEPS=N (the smoke tests set it) caps every loop at N steps and the race at 3 s
SMOKE_STEPS = os.environ.get("SOFAR_EXAMPLE_STEPS")


def max_steps(default: int) -> int:
    return int(SMOKE_STEPS) if SMOKE_STEPS else default


def race_seconds(default: float) -> float:
    return 3.0 if SMOKE_STEPS else default


def write_centerline(path: Path, n: int = 400) -> None:
    """A closed, smooth circuit of about 1.6 km with 12 m wide track."""
    t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    x = 400.0 * np.cos(t)
    y = 180.0 * np.sin(t) + 30.0 * np.sin(2.0 * t)
    rows = np.column_stack([x, y, np.full(n, 6.0), np.full(n, 6.0)])
    np.savetxt(path, rows, delimiter=",", header="x_m,y_m,w_tr_right_m,w_tr_left_m", comments="", fmt="%.4f")


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        csv = Path(tmp) / "oval.csv"
        out = Path(tmp) / "Oval"
        write_centerline(csv)
        subprocess.run([sys.executable, "-m", "sofar_env.tracks", "build", str(csv), "--name", "Oval",
                        "--out", str(out), "--format", "centerline"], check=True)
        env = gym.make("SOfAR-Custom-v0", track=out, race={"duration": race_seconds(20.0)})
        env.reset(seed=0)
        for _ in range(max_steps(10_000)):
            _, _, terminated, truncated, info = env.step(np.array([0.3], dtype=np.float32))
            if terminated or truncated:
                break
        env.close()
        print(f"raced on {out.name}: overtakes {info.get('overtakes')}, collision {info.get('collision')}")


if __name__ == "__main__":
    main()
