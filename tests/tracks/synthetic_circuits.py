"""Small synthetic circuits for the builder tests: circles and an edges CSV writer.

Imported as ``synthetic_circuits`` (this folder is on the path when pytest runs its tests).
"""

from __future__ import annotations

import math

import numpy as np

R = 60.0  # [m] radius of the synthetic circles


def circle(radius: float, count: int, phase: float = 0.0, ccw: bool = True, center=(10.0, -5.0)) -> np.ndarray:
    ang = phase + np.linspace(0.0, 2.0 * math.pi, count, endpoint=False)
    if not ccw:
        ang = ang[::-1]
    return np.column_stack([center[0] + radius * np.cos(ang), center[1] + radius * np.sin(ang)])


def write_edges(path, left: np.ndarray, right: np.ndarray) -> None:
    """Edges CSV without header; the edges have different sample counts (NaN padding)."""
    rows = max(len(left), len(right))
    data = np.full((rows, 4), np.nan)
    data[: len(left), :2] = left
    data[: len(right), 2:] = right
    lines = [",".join("" if math.isnan(v) else f"{v:.6f}" for v in row) for row in data]
    path.write_text("\n".join(lines) + "\n")
