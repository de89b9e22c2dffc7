"""Defending against the ego: one blocking move per approach, none once the ego is alongside.

Per car and episode an aggressiveness is drawn: 0 with probability
``never_defend`` (the car never defends), otherwise uniform in the configured
range; it scales the lateral speed of the car's move. The state machine of one
car, with ``gap = s_car - s_ego`` (> 0: the ego is behind) and ``closing`` the
ego's arc-length speed minus the car's:

* an *approach* starts when the ego enters the window ``[min_gap, max_gap]`` and
  ends when it falls back beyond ``max_gap + release`` or has passed (gap below
  minus the alongside distance); a respawned car starts without one;
* during an approach, while no move has been made, the ego is in the window, not
  alongside, closing by at least ``min_closing`` and at least ``trigger`` to one
  side, the car makes its move: it steers toward the ego's lateral offset of that
  moment (the *target*) and then holds it until the approach ends;
* once the ego is alongside (``|gap| < car length + alongside_margin``) a move
  in progress stops where the car is; no new move is made.

Separately, :func:`ego_guarded` says when the car must not close sideways on the
ego at all (the ego alongside, or about to be within ``guard_time``): the field
then bounds every lateral motion, line following included.

This follows the etiquette of racing commonly modelled in research on opponent
behaviour (one defensive move per approach, no move once the attacker is
alongside); the blocking toward the attacker's lateral offset, weighted per
episode, is the blocking rule of the reactive opponents of the game-racer project
(wulemao/game-racer, ``racing_comp_blocking.py``), made a single move.
"""

from __future__ import annotations

import numpy as np

from .._jit import kernel, py_max
from .config import DefenceConfig

__all__ = ["HOLDING", "IDLE", "MOVING", "Defence", "defence_step", "ego_guarded", "guarded"]

IDLE, MOVING, HOLDING = 0, 1, 2
"""Modes of a car: following its line; making its move; holding the offset it moved to."""

_ARRIVED = 0.05
"""A move ends (the car holds) once the car is this close to its target [m] and this slow [m/s]."""


def ego_guarded(gap: float, closing: float, cfg: DefenceConfig, car_length: float, lead: float = 0.0) -> bool:
    """Whether the ego is alongside the car or will be within ``guard_time + lead`` [s] at the current
    closing speed (:func:`guarded`)."""
    return guarded(float(gap), float(closing), car_length + cfg.alongside_margin, cfg.guard_time, float(lead))


@kernel
def guarded(gap, closing, along, guard_time, lead):
    """:func:`ego_guarded` with ``along = car_length + alongside_margin`` [m] (inside kernels)."""
    horizon = guard_time + lead
    ahead = along + py_max(closing, 0.0) * horizon  # the ego closing from behind
    behind = along + py_max(-closing, 0.0) * horizon  # the car closing on an ego ahead of it
    return -behind < gap < ahead


class Defence:
    """Defence state of ``m`` cars (arrays indexed by car)."""

    def __init__(self, m: int, cfg: DefenceConfig, rng: np.random.Generator, car_length: float):
        self.cfg = cfg
        self.car_length = float(car_length)
        u = rng.uniform(size=(m, 2))  # drawn also when defence is off, so other draws do not depend on it
        lo, hi = cfg.aggressiveness
        aggr = lo + (hi - lo) * u[:, 1]
        self.aggressiveness = np.where(u[:, 0] < cfg.never_defend, 0.0, aggr) if cfg.enabled else np.zeros(m)
        """Aggressiveness of each car [-]; 0: never defends."""
        self.approach = np.zeros(m, bool)
        self.used = np.zeros(m, bool)
        self.mode = np.full(m, IDLE)
        self.target = np.zeros(m)
        """Offset a moving or holding car steers to [m]."""
        self.moves = np.zeros(m, int)
        """Moves made by each car in this episode."""

    def forget(self, i: int) -> None:
        """Fresh per-approach state for car ``i`` (after a respawn)."""
        self.approach[i] = self.used[i] = False
        self.mode[i] = IDLE

    def update(self, i: int, gap: float, closing: float, n_car: float, n_dot: float, n_ego: float) -> None:
        """Advance the state machine of car ``i`` (see the module docstring; :func:`defence_step`)."""
        cfg = self.cfg
        defence_step(i, float(gap), float(closing), float(n_car), float(n_dot), float(n_ego), self.aggressiveness,
                     self.approach, self.used, self.mode, self.target, self.moves, self.car_length + cfg.alongside_margin,
                     cfg.min_gap, cfg.max_gap, cfg.release, cfg.min_closing, cfg.trigger)

    def limits(self, i: int) -> tuple[float, float]:
        """Bounds on the lateral speed [m/s] and acceleration [m/s^2] of car ``i``'s move."""
        return self.aggressiveness[i] * self.cfg.lateral_speed, self.cfg.lateral_accel


@kernel
def defence_step(i, gap, closing, n_car, n_dot, n_ego, aggressiveness, approach, used, mode, target, moves, along,
                 min_gap, max_gap, release, min_closing, trigger):
    """:meth:`Defence.update` of car ``i`` on the state arrays of :class:`Defence` (changed in place), with
    ``along = car_length + alongside_margin`` [m] and the other :class:`DefenceConfig` fields."""
    if aggressiveness[i] <= 0.0:
        return
    alongside = abs(gap) < along
    in_window = min_gap <= gap <= max_gap and not alongside
    if approach[i] and (gap > max_gap + release or gap <= -along):
        approach[i] = used[i] = False  # Defence.forget
        mode[i] = IDLE
    if not approach[i]:
        if not in_window:
            return
        approach[i], used[i] = True, False
    m = mode[i]
    if m == MOVING and alongside:
        mode[i], target[i] = HOLDING, n_car
    elif m == IDLE and not used[i] and in_window and closing >= min_closing and abs(n_ego - n_car) >= trigger:
        used[i], mode[i], target[i] = True, MOVING, n_ego
        moves[i] += 1
    elif m == MOVING and abs(target[i] - n_car) < _ARRIVED and abs(n_dot) < _ARRIVED:
        mode[i] = HOLDING
