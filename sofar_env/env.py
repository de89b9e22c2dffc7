"""Gymnasium environment: the overtaking stack of the paper, with the barrier decay gamma as the action.

A thin adapter over :class:`~sofar_env.core.ControlledRace` (one controlled car): spaces,
seeding, the Gymnasium return conventions and rendering.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from .config import OBJECTIVE_NAMES, EnvConfig, make_env_config
from .constants import GAMMA_MAX, GAMMA_MIN
from .core import ControlledRace, parse_gamma
from .errors import ResetNeeded as _ResetNeeded
from .observation import observation_size
from .snapshot import Snapshots

__all__ = ["SOfARRaceEnv", "ResetNeeded", "GAMMA_MIN", "GAMMA_MAX", "RESET_OPTIONS"]

RESET_OPTIONS = ("rho", "n_opponents", "start_s", "start_speed")
"""Keys accepted in ``reset(options=...)``."""


class ResetNeeded(_ResetNeeded, gym.error.ResetNeeded):
    """``step()`` or ``render()`` with no episode running: a ``RuntimeError`` and Gymnasium's ``ResetNeeded``."""


class SOfARRaceEnv(Snapshots, gym.Env):
    r"""Safe overtaking on a real circuit: learn the barrier decay gamma of an MPC-DCBF controller.

    ## Description

    The ego car (a Dallara AV-21, kinematic bicycle with slip) races a field of slower
    opponents that follow the raceline at a pace ratio rho of the circuit's speed
    profile. It is driven by the hierarchical controller of the paper
    (:class:`~sofar_env.stack.OvertakingStack`, Algorithm 1): a passing-side MIQP
    chooses a lateral reference, an MPC with discrete-time control barrier functions
    tracks it while keeping ``h(x_{k+1}) >= (1 - gamma) h(x_k)`` for a velocity-aware
    elliptic barrier h around every opponent. The agent chooses gamma: small values
    keep the car far from the opponents (cautious), values near 1 let it close in
    quickly (aggressive). An opponent that has been ahead and falls 2 m behind counts
    as overtaken and reappears 400 m ahead. The world runs at dt = 0.1 s.

    ## Action Space

    ``Box(0.05, 1.0, (1,), float32)``: gamma, the decay of the barrier condition.
    A non-finite action raises ``ValueError``; a finite value outside [0.05, 1] is
    clipped into it (gamma = 0 would freeze the barrier, > 1 would be meaningless).
    The policy acts every ``decision_interval`` control steps (default 1); gamma is
    held in between.

    ## Observation Space

    ``Box(-1, 1, (12,), float32)``, the paper's 12 values in the global Frenet frame
    of the raceline (s along it, n > 0 to the left). Each physical value is clipped to
    its range [lo, hi] and mapped affinely onto [-1, 1]; an absent opponent reads as
    far away (gap 200 m, n 0, dv 0), never as a sentinel.

    | Num | Observation                                        | Unit | Range [lo, hi] | Scaled value |
    |-----|----------------------------------------------------|------|----------------|--------------|
    | 0   | ego lateral offset n from the raceline             | m    | [-15, 15]      | n / 15       |
    | 1   | ego speed v                                        | m/s  | [0, 100]       | v / 50 - 1   |
    | 2   | steering angle delta                               | rad  | [-0.25, 0.25]  | delta / 0.25 |
    | 3   | gap s_opp - s_ego to opponent 1                    | m    | [-20, 200]     | (g + 20) / 110 - 1 |
    | 4   | gap to opponent 2                                  | m    | [-20, 200]     | (g + 20) / 110 - 1 |
    | 5   | lateral offset n of opponent 1                     | m    | [-15, 15]      | n / 15       |
    | 6   | lateral offset n of opponent 2                     | m    | [-15, 15]      | n / 15       |
    | 7   | closing speed v_ego - v_opp of opponent 1          | m/s  | [-50, 50]      | dv / 50      |
    | 8   | closing speed of opponent 2                        | m/s  | [-50, 50]      | dv / 50      |
    | 9   | mean raceline curvature over the next 1.5 s        | 1/m  | [-0.05, 0.05]  | kappa / 0.05 |
    | 10  | raceline-to-left-edge distance at the ego          | m    | [0, 15]        | w / 7.5 - 1  |
    | 11  | raceline-to-right-edge distance at the ego         | m    | [0, 15]        | w / 7.5 - 1  |

    Opponents 1 and 2 are the two nearest with a gap in [-20, 200] m, in ascending order
    of gap (a car alongside or just behind comes first). Opponent speeds are arc-length
    speeds ds/dt. The curvature is averaged over 16 points from s to s + 1.5 s x max(v, 5 m/s).
    See :mod:`sofar_env.observation`.

    With ``observation="extended"`` (the default of the ``-Interactive-v0`` ids) the space is
    ``Box(-1, 1, (16,), float32)``: the 12 values above and

    | Num | Observation                                        | Unit | Range [lo, hi] | Scaled value |
    |-----|----------------------------------------------------|------|----------------|--------------|
    | 12  | sensed lateral rate of opponent 1                  | m/s  | [-3, 3]        | r / 3        |
    | 13  | sensed lateral rate of opponent 2                  | m/s  | [-3, 3]        | r / 3        |
    | 14  | heading error e (ego heading - raceline heading)   | rad  | [-0.5, 0.5]    | e / 0.5      |
    | 15  | smallest barrier value h over the sensed opponents | -    | [-1, 9]        | (h + 1) / 5 - 1 |

    what a good gamma depends on in a world of moving, noisily sensed cars: whether the nearest
    cars are moving across, how the ego is pointed, and the instantaneous safety margin.

    ## Rewards

    A vector of five named objectives (``env.unwrapped.objective_names``), each summed
    over the control steps of one decision:

    | Objective          | Per control step                                                       | Range      |
    |--------------------|------------------------------------------------------------------------|------------|
    | `safety`           | -1 on a collision or when a corner of the car leaves the track, else 0 | {-1, 0}    |
    | `overtakes`        | +1 per opponent overtaken                                              | {0, 1, ..} |
    | `progress`         | arc length gained / (speed profile at the ego x dt): ~1 at the profile speed, ~0.8 at the default speed_factor | ~[0, 1.3] |
    | `barrier_margin`   | -min(1, slack + max(0, -min h)): slack = largest DCBF slack of the MPC solution, min h = smallest barrier value over the opponents after the step | [-1, 0] |
    | `gamma_smoothness` | -abs(gamma_t - gamma_{t-1}) (gamma_{-1} = ``initial_gamma``, 0.5)      | [-0.95, 0] |

    ``reward_mode="scalar"`` (default) returns the Python float ``w . r`` with
    ``reward_weights`` (default w = (10, 1, 0.05, 0.5, 0.1): a crash outweighs ten
    overtakes; a 200 s race at the default speed factor is worth about 80 of progress;
    a step that uses a full unit of barrier slack costs 0.5). ``reward_mode="vector"``
    returns the float32 vector and declares it in ``env.unwrapped.reward_space``
    (MO-Gymnasium convention; scalarise it outside the env). Only the vector mode declares a
    ``reward_space``: a scalar-mode env is not a multi-objective env, and MO-Gymnasium's wrappers
    (which read ``env.unwrapped.reward_space``) refuse it with an ``AttributeError`` that names
    ``reward_mode="vector"``, instead of copying the scalar into every objective. So pass
    ``reward_mode="vector"`` to ``mo_gymnasium.make(...)`` as to plain ``gymnasium.make(...)`` (the
    registered ids leave Gymnasium's passive checker, which expects a float reward, off in vector mode;
    :mod:`sofar_env.factory`) and use MO-Gymnasium's wrappers (``LinearReward``,
    ``MORecordEpisodeStatistics`` inside the scalarisation). ``gymnasium.make_vec(id, num_envs,
    reward_mode="vector")`` returns ``mo_gymnasium.wrappers.vector.MOSyncVectorEnv`` (the ids' vector
    entry point); ``gymnasium.vector.SyncVectorEnv`` stores scalar rewards only. The vector is always in
    ``info["reward_vector"]``.

    ## Starting State

    The ego starts on the raceline (n = 0, aligned with it, steering 0) at an arc
    length drawn uniformly on the lap and a speed drawn uniformly in [0.5, 0.9] x the
    speed profile there. The opponents start 120, 180, 250 and 400 m ahead at lateral
    offsets 0, +1, -1, 0 m. ``reset(options=...)`` may set ``start_s`` [m],
    ``start_speed`` [m/s], ``rho`` and ``n_opponents`` for that episode. All randomness
    comes from ``self.np_random``: the same seed and actions give the same trajectory.

    ## Episode End

    * Termination: a collision (the 4.9 m x 1.9 m footprints intersect), a corner of
      the ego's footprint beyond a track edge, or a stall: the ego slower than
      ``stall_speed`` (1 m/s) for ``stall_seconds`` (20 s) without interruption, e.g.
      stopped for good behind a car it cannot pass (``info["stalled"]``; ``stall_seconds=None``
      or 0 turns the rule off).
    * Truncation: the race duration (``race.duration``, 200 s = 2000 control steps of ``race.dt`` = 0.1 s by
      default). The environment truncates itself there, whatever the duration, time step and decision
      interval; the registered ids add no ``TimeLimit`` of their own (``gymnasium.make(...,
      max_episode_steps=N)`` still adds one).
    * After the end, ``step()`` raises :class:`ResetNeeded` (a ``RuntimeError``) and changes nothing, as
      it does before the first successful ``reset()``; a ``reset()`` that raises leaves the environment as
      it was (an episode it interrupted goes on; before any episode, the next ``reset()`` starts one).

    ``info["is_success"]`` is set at the end of an episode: True when the duration was
    reached without a collision, leaving the track or stalling.

    ## Info

    ``reward_vector`` (float32, 5), ``cost`` (barrier slack + collisions + off-tracks, for
    constrained RL), ``overtakes`` (episode total), ``laps`` (arc length driven / lap
    length), ``sim_time`` [s], ``gamma``, ``collision``, ``off_track``, ``stalled``
    (the stall rule ended the episode), ``nearest_opponent_m`` (distance between reference points [m], inf if none),
    ``min_barrier`` (min h over the opponents now, inf if none), ``barrier_slack``,
    ``mpc_status``, ``miqp_sides`` (per opponent the planners saw, nearest first: +1 = the plan passes it
    on the left, -1 = on the right, 0 = not constrained by the plan),
    ``mpc_failures``, ``miqp_failures``, ``parked_checks``, ``mpc_restarts`` (episode counters;
    ``parked_checks``: MIQP calls that planned the pass of near-stationary opponents with the parked
    clearance, see :mod:`sofar_env.stack.follow`; ``mpc_restarts``: MPC solves repeated from a cold
    guess, ``stack.mpc.restart_slack``, 0 unless it is set, as in multi-car races), ``is_success`` at the end. With
    ``timing_info=True`` also the wall-clock solve times ``mpc_time_ms``, ``miqp_time_ms`` of
    the step: off by default, because they are the only values that differ between two runs
    with the same seed, and checks that compare infos exactly (Gymnasium's ``check_env``,
    PettingZoo's seed test) would fail; the benchmark scripts in ``eval/`` turn them on.

    ## Arguments

    ```python
    import gymnasium as gym
    import sofar_env
    env = gym.make("SOfAR-LagunaSeca-v0", rho=0.5, decision_interval=2, render_mode="rgb_array")
    env = gym.make("SOfAR-Monza-v0", config={"reward_mode": "vector", "race": {"duration": 60.0}})
    ```

    A circuit of your own: ``gym.make("SOfAR-Custom-v0", track="path/to/folder")`` (a folder written by
    ``python -m sofar_env.tracks build``, or a :class:`~sofar_env.tracks.Track`).

    Keyword arguments and the ``config`` mapping are validated into
    :class:`~sofar_env.config.EnvConfig` (unknown keys raise ``ValueError``): ``track``,
    ``n_opponents``, ``offsets``, ``rho``, ``speed_factor``, ``use_miqp``,
    ``decision_interval``, ``reward_mode``, ``reward_weights``, ``initial_gamma``, ``stall_speed``,
    ``stall_seconds``, ``timing_info``,
    ``race`` (:class:`~sofar_env.race.RaceConfig`), ``stack``
    (:class:`~sofar_env.stack.StackConfig`, or a preset name: ``"sofar"``, the default, or
    ``"paper"``, the paper's Algorithm 1 as written, see :func:`~sofar_env.stack.stack_preset`).
    The controllers are built on the first
    ``reset()``, so constructing the environment is cheap.

    ## Copies and saved states

    ``copy.deepcopy(env)``, ``pickle`` and ``cloudpickle`` copy a running environment (wrapped or not): the
    copy continues exactly as the original would under the same actions, to the bit. Compiled parts are not
    serialised but built again from the configuration (the CasADi library is loaded from its disk cache,
    nothing is compiled; PIQP is set up again in the state of the original's solver); a renderer is not
    copied. ``env.unwrapped.get_state()`` saves the current moment and ``env.unwrapped.set_state(state)``
    returns to it (:class:`~sofar_env.snapshot.EnvState`; wrappers' own counters are not part of it).

    ## Version History

    * v0: initial version. The ``observation`` key (``"extended"``: 16 values) came with the interactive
      world; the paper world's 12 values are unchanged.
    """

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 10}

    def __init__(self, config: EnvConfig | Mapping[str, Any] | None = None, render_mode: str | None = None,
                 **kwargs: Any):
        self.config = make_env_config(config, **kwargs)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']} or None, got {render_mode!r}")
        self.render_mode = render_mode
        cfg = self.config
        k = cfg.decision_interval
        self.action_space = spaces.Box(GAMMA_MIN, GAMMA_MAX, (1,), np.float32)
        self.observation_space = spaces.Box(-1.0, 1.0, (observation_size(cfg.observation),), np.float32)
        self.objective_names = OBJECTIVE_NAMES
        if cfg.reward_mode == "vector":  # a scalar-mode env declares none: it is not a multi-objective env
            self.reward_space = spaces.Box(
                low=np.array([-1.0, 0.0, -2.0 * k, -1.0 * k, -1.0], np.float32),
                high=np.array([0.0, float(k * max(cfg.n_opponents, 1)), 2.0 * k, 0.0, 0.0], np.float32),
                dtype=np.float32,
            )
        self.core = ControlledRace(cfg)
        """The simulation core: the race world and the controller of the ego (car 0)."""
        self._renderer = None

    _state_attributes = ("core", "_np_random", "_np_random_seed")  # what get_state() saves

    def __getattr__(self, name: str):
        if name == "reward_space":  # only looked up here when the instance has none: scalar mode
            raise AttributeError("reward_space is declared only with reward_mode='vector' (the step then returns the "
                                 "reward vector); this env returns the scalar weights . vector")
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    # read-only views of the core, for users and the renderer
    @property
    def track(self):
        return self.core.track

    @property
    def race(self):
        return self.core.race

    @property
    def stack(self):
        return self.core.stacks[0] if self.core.stacks else None

    @property
    def last_output(self):
        """The controller output of the last control step (MPC prediction, MIQP plan), for rendering."""
        return self.core.outputs[0]

    # ------------------------------------------------------------------ API
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        options = dict(options or {})
        unknown = set(options) - set(RESET_OPTIONS)
        if unknown:
            raise ValueError(f"unknown reset option(s) {sorted(unknown)}; valid: {', '.join(RESET_OPTIONS)}")
        self.core.check_reset(**options)  # before anything changes: a failed reset leaves the env as it was
        super().reset(seed=seed)
        first = self.core.reset(self.np_random, **options)[0]
        if self.render_mode == "human":
            self.render()
        return first.observation, first.info

    def step(self, action):
        if not self.core.running:
            raise ResetNeeded(self.core.not_running_message())
        result = self.core.step({0: parse_gamma(action)})[0]
        if self.render_mode == "human":
            self.render()
        return result.observation, result.reward, result.terminated, result.truncated, result.info

    def render(self):
        if self.render_mode is None:
            gym.logger.warn(
                "render() called without a render_mode; pass render_mode='rgb_array' or 'human' to the constructor"
            )
            return None
        if not self.core.started:
            raise ResetNeeded(self.core.not_running_message("render()"))
        if self._renderer is None:
            from .render import Renderer

            self._renderer = Renderer(self.track, self.config.race.vehicle, self.config.stack.mpc.barrier,
                                      fps=self.metadata["render_fps"])
        frame = self.core.render_frame(self._renderer, 0)
        if self.render_mode == "human":
            self._renderer.show(frame)
            return None
        return frame

    def close(self):
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
        super().close()
