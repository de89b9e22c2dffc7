"""Protocol constants, defined once: circuits, pace ratios, the gamma range.

Everything else imports these names; nothing redefines them.
"""

from __future__ import annotations

__all__ = [
    "CIRCUITS",
    "TABLE_ORDER",
    "CIRCUIT_ABBREVIATIONS",
    "RHOS",
    "FIXED_GAMMAS",
    "GAMMA_MIN",
    "GAMMA_MAX",
    "EPISODE_SECONDS",
    "MAX_SPEED_FACTOR",
]

CIRCUITS: tuple[str, ...] = ("LagunaSeca", "Monza", "Indianapolis", "Kentucky")
"""The four shipped circuits (folder names under ``tracks/``), in registration order."""
TABLE_ORDER: tuple[str, ...] = ("Indianapolis", "Kentucky", "LagunaSeca", "Monza")
"""The same circuits in the row order of the paper's Table I."""
CIRCUIT_ABBREVIATIONS: dict[str, str] = {"Indianapolis": "IMS", "Kentucky": "KS", "LagunaSeca": "LS",
                                         "Monza": "Monza"}
"""Short names used in the paper's tables."""
RHOS: tuple[float, ...] = (0.1, 0.3, 0.5, 0.65, 0.8)
"""Opponent pace ratios of the paper's evaluation protocol [-]."""
FIXED_GAMMAS: tuple[float, ...] = (0.05, 0.15, 0.30, 0.50, 0.70, 0.95)
"""Fixed barrier decays of the paper's baselines [-]."""
GAMMA_MIN: float = 0.05
"""Smallest barrier decay an action can ask for [-] (the paper's action range)."""
GAMMA_MAX: float = 1.0
"""Largest barrier decay [-]: gamma = 1 lets the barrier reach 0 in one step."""
EPISODE_SECONDS: float = 200.0
"""Episode horizon of the paper's protocol [s] (2000 control steps at dt = 0.1 s)."""
MAX_SPEED_FACTOR: float = 1.5
"""Largest speed factor of a controller (``StackConfig.speed_factor``, ``RaceConfig.pace_range``) [-]."""
