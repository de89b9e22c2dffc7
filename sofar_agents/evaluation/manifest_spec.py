"""What a manifest (``experiments/NAME.toml``) holds: :class:`Manifest`, read by :func:`load_manifest`.

A manifest is a TOML file (``tomllib``, in the standard library from Python 3.11; on 3.10 the ``tomli``
package if installed). TOML rather than JSON: it holds comments (why a table exists, what it is compared
with) and reads like the command line it replaces. Keys (:class:`Manifest`):

=================  ========================================================================================
``kind``           ``"table1"`` (:func:`~sofar_agents.evaluation.experiments.run_table1`), ``"table2"``
                   (:func:`~sofar_agents.evaluation.experiments.run_miqp_ablation`), ``"multi-agent"``
                   (:func:`~sofar_agents.evaluation.multi_agent.run_multi_agent_table`), ``"pareto"``
                   (:func:`~sofar_agents.evaluation.pareto.run_pareto`), ``"interventions"``
                   (:func:`~sofar_agents.evaluation.interventions.replay_interventions`), ``"figures"``
                   (Fig. 5: :func:`~sofar_agents.evaluation.figures.record_figure_episodes`, then
                   :func:`~sofar_agents.evaluation.figures.plot_gamma_figures`), ``"standing-start"`` (the
                   standing-start probe of one controller:
                   :func:`~sofar_agents.evaluation.standing_start.run_probe_manifest`) or ``"floor"`` (a policy
                   replayed with its gamma floored in chosen states:
                   :func:`~sofar_agents.evaluation.gamma_floor.run_floor_study`); required
``out``            the results folder, relative to the repository root; required
``stack``          controller preset (default ``"sofar"``); ``scenario``: world (default ``"paper"``)
``seed``           base seed of the paired episode seeds (default 0)
``episodes``       per (track, rho) for table1, pareto, figures and floor, per (setting, strategy) for table2, races
                   per circuit for multi-agent (defaults 5, 5, 3, 10, 4)
``duration``       episode horizon [s] (default 200)
``tracks``,        circuits and pace ratios (defaults: the paper's; ``track``: table2's circuit, default
``rhos``           LagunaSeca)
``gammas``         the fixed gammas (default: the paper's six; table2 and standing-start: [0.5], standing-start
                   one only; figures: none); interventions: the gammas switched to inside the window (default
                   [0.15, 0.3, 0.6])
``adaptive``       also the shipped PASTA policy of ``stack``/``scenario`` (default true); ``policy``: another
                   checkpoint, relative to the repository root
``safety_weights`` pareto: the policy's preferences (:func:`~sofar_agents.evaluation.pareto.preference_family`;
                   default [0.1, 0.3, 0.5, 0.7, 0.9])
``self_play``      multi-agent: a second checkpoint (relative to the root), the strategy ``self-play``
``opponents``      table1, pareto: opponents per episode (default: the environment's); multi-agent: scripted
                   opponents
``cars``           multi-agent: controlled cars (default 4)
``sources``        interventions: the per-episode CSVs (relative to the root) whose failed episodes are replayed
``base_gamma``     interventions: the fixed gamma whose failures are replayed (default 0.05)
``windows``,       interventions: how long before the failure the window opens [s] (default [1, 2, 4]) and
``hold``           stays open after it [s] (default 2)
``placebo_delta``, interventions: the placebos' gamma change (default 0.01) and shift [s] (default 20)
``placebo_lead``
``limit``          interventions: at most this many failed episodes per source CSV (default: all)
``prefix``         file prefix in ``out`` (default ``table1``, ``table2``, ``multi_agent``, ``pareto``; figures
                   write ``episodes.csv`` and ``trace.csv`` and take none)
``count``,        standing-start: arc lengths per circuit (default 25) and the distances of the car's side from
``clearances``     the edge [m] (default [0.5, 0.3, 0.15])
``drive_time``,    standing-start: simulated seconds per placement (default 8) and the arc length a run must
``min_distance``   gain to count as driving off [m] (default 5)
``floor``,        floor: the gamma floor (default 0.15), where it holds (default ["always", "far", "near"]), the
``where``,         distance that separates near from far [m] (default 20) and whether every step is recorded
``radius``,        (default false); the policy runs at the one preference of ``safety_weights`` (one weight, given),
``trace``          beside the fixed ``gammas`` (default [0.05, 0.15, 0.3, 0.5])
``description``    free text
=================  ========================================================================================

The interventions' episodes take their controller, world and horizon from the rows of ``sources``; a
manifest states them too (``stack``, ``scenario``, ``duration``: its configuration hash), and a source
episode of other settings is an error.
"""

from __future__ import annotations

import dataclasses
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sofar_agents.evaluation.configs import episode_config, episode_config_hash, race_config, race_config_hash
from sofar_agents.evaluation.protocol import DEFAULT_DURATION, FIXED_GAMMAS, RHOS, TRACKS, Strategy, build_strategies

__all__ = ["KINDS", "Manifest", "load_manifest", "manifest_paths"]

KINDS = ("table1", "table2", "multi-agent", "pareto", "interventions", "figures", "standing-start", "floor")
"""Command kinds a manifest may name."""
DEFAULT_EPISODES = {"table1": 5, "pareto": 5, "figures": 3, "table2": 10, "multi-agent": 4, "floor": 2}
"""Episodes per cell (races per circuit for multi-agent) of a manifest without ``episodes``, by kind."""
DEFAULT_SAFETY_WEIGHTS = (0.1, 0.3, 0.5, 0.7, 0.9)
"""Safety weights of a pareto manifest's preferences (those of ``eval/pareto.py``)."""
DEFAULT_SWITCH_GAMMAS = (0.15, 0.3, 0.6)
"""Gammas inside the window of an interventions manifest (those of ``eval/interventions.py``)."""
_TUPLES = ("tracks", "rhos", "gammas", "safety_weights", "sources", "windows", "clearances", "where")


def _toml_load(path: Path) -> dict[str, Any]:
    try:
        import tomllib
    except ModuleNotFoundError:  # Python 3.10
        try:
            import tomli as tomllib  # type: ignore[no-redef]
        except ModuleNotFoundError as err:
            raise RuntimeError("reading experiment manifests on Python 3.10 needs the tomli package "
                               "(pip install tomli); Python >= 3.11 reads them without it") from err
    with open(path, "rb") as f:
        return tomllib.load(f)


@dataclass(frozen=True)
class Manifest:
    """One experiment (the module docstring lists the keys)."""

    name: str
    kind: str
    out: str
    stack: str = "sofar"
    scenario: str = "paper"
    seed: int = 0
    episodes: int | None = None
    duration: float = DEFAULT_DURATION
    tracks: tuple[str, ...] = TRACKS
    rhos: tuple[float, ...] = RHOS
    track: str = "LagunaSeca"
    gammas: tuple[float, ...] | None = None
    adaptive: bool = True
    policy: str | None = None
    safety_weights: tuple[float, ...] = DEFAULT_SAFETY_WEIGHTS
    self_play: str | None = None
    opponents: int | None = None
    cars: int = 4
    sources: tuple[str, ...] = ()
    base_gamma: float = 0.05
    windows: tuple[float, ...] = (1.0, 2.0, 4.0)
    hold: float = 2.0
    placebo_delta: float = 0.01
    placebo_lead: float = 20.0
    limit: int | None = None
    prefix: str | None = None
    count: int = 25
    clearances: tuple[float, ...] = (0.5, 0.3, 0.15)
    drive_time: float = 8.0
    min_distance: float = 5.0
    floor: float = 0.15
    where: tuple[str, ...] | None = None
    radius: float = 20.0
    trace: bool = False
    description: str = ""

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"manifest {self.name}: kind {self.kind!r} is not one of {', '.join(KINDS)}")
        if (self.kind == "interventions") != bool(self.sources):
            raise ValueError(f"manifest {self.name}: sources is the (required) key of the interventions kind")
        if self.kind in ("figures", "standing-start") and self.prefix is not None:
            raise ValueError(f"manifest {self.name}: a {self.kind} folder has fixed file names; no prefix")
        if self.kind == "standing-start":
            self._check_probe()
        if self.kind == "floor":
            self.floors()  # raises for a bad floor, place or radius
            if len(self.safety_weights) != 1:
                raise ValueError(f"manifest {self.name}: a floor study runs the policy at one preference; "
                                 f"safety_weights must hold one weight, got {list(self.safety_weights)}")

    def floors(self) -> list:
        """The :class:`~sofar_agents.evaluation.gamma_floor.GammaFloor` of a floor manifest, one per ``where``
        (None: every place, :data:`~sofar_agents.evaluation.gamma_floor.WHERES`)."""
        from sofar_agents.evaluation.gamma_floor import WHERES, GammaFloor

        if self.where is not None and not self.where:
            raise ValueError(f"manifest {self.name}: where must name at least one place")
        try:
            return [GammaFloor(self.floor, w, self.radius) for w in (WHERES if self.where is None else self.where)]
        except ValueError as err:
            raise ValueError(f"manifest {self.name}: {err}") from err

    @property
    def floor_gammas(self) -> tuple[float, ...]:
        """The fixed gammas of a floor manifest: ``gammas``, else
        :data:`~sofar_agents.evaluation.gamma_floor.FLOOR_GAMMAS`."""
        from sofar_agents.evaluation.gamma_floor import FLOOR_GAMMAS

        return FLOOR_GAMMAS if self.gammas is None else self.gammas

    def _check_probe(self) -> None:
        """The keys of a standing-start manifest."""
        if self.gammas is not None and len(self.gammas) != 1:
            raise ValueError(f"manifest {self.name}: a standing-start probe drives one fixed gamma, got {self.gammas}")
        if self.duration != DEFAULT_DURATION:
            raise ValueError(f"manifest {self.name}: duration is the environment's episode horizon, "
                             f"{DEFAULT_DURATION:g} s in the probe; its run length is drive_time")
        if not (isinstance(self.count, int) and self.count >= 1):
            raise ValueError(f"manifest {self.name}: count must be an integer >= 1, got {self.count!r}")
        for key in ("drive_time", "min_distance"):
            value = getattr(self, key)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0.0):
                raise ValueError(f"manifest {self.name}: {key} must be a finite number > 0, got {value!r}")
        if not self.clearances or not all(isinstance(c, (int, float)) and math.isfinite(c) and c >= 0.0
                                          for c in self.clearances):
            raise ValueError(f"manifest {self.name}: clearances must be finite numbers >= 0 [m], got "
                             f"{self.clearances!r}")

    @property
    def episode_count(self) -> int:
        """``episodes``, else the kind's default (:data:`DEFAULT_EPISODES`)."""
        return self.episodes or DEFAULT_EPISODES.get(self.kind, 5)

    @property
    def csv_name(self) -> str:
        """The file of its rows in ``out``."""
        if self.kind == "multi-agent":
            return f"{self.prefix or 'multi_agent'}_races.csv"
        if self.kind == "interventions":
            return "interventions.csv"
        if self.kind == "figures":
            return "episodes.csv"
        if self.kind == "standing-start":
            from sofar_agents.evaluation.standing_start import CSV_NAME

            return CSV_NAME
        return f"{self.prefix or self.kind}_episodes.csv"

    @property
    def config_hash(self) -> str:
        """The configuration hash its rows carry (:mod:`sofar_agents.evaluation.configs`)."""
        if self.kind == "multi-agent":
            return race_config_hash(self.stack, self.scenario, self.duration, int(self.opponents or 0))
        return episode_config_hash(self.stack, self.scenario, self.duration)

    def config(self) -> Any:
        """The resolved configuration of that hash (what ``config.json`` records)."""
        if self.kind == "multi-agent":
            return race_config(self.stack, self.scenario, float(self.duration), int(self.opponents or 0))
        return episode_config(self.stack, self.scenario, float(self.duration))

    def policy_path(self, root: str | os.PathLike) -> Path:
        """The adaptive policy: ``policy`` (relative to ``root``), else the one shipped for ``stack`` and
        ``scenario``; ``FileNotFoundError`` when there is none (a manifest does not silently drop a row)."""
        from sofar_agents.evaluation.protocol import resolve_policy_path

        policy = resolve_policy_path(Path(root) / self.policy if self.policy else None, stack=self.stack,
                                     scenario=self.scenario)
        if policy is None:
            raise FileNotFoundError(f"manifest {self.name}: no adaptive policy for stack {self.stack!r}")
        return policy

    def strategies(self, root: str | os.PathLike) -> list[Strategy]:
        """Its strategies: the adaptive policy (``policy``, else the shipped one) when ``adaptive``, then the
        fixed gammas; pareto: the fixed gammas, then the policy at each preference; interventions: the base
        gamma (the strategy of the replayed episodes). A missing policy raises ``FileNotFoundError``."""
        if self.kind == "interventions":
            return [Strategy.fixed(self.base_gamma)]
        if self.kind == "standing-start":
            return [Strategy.fixed((self.gammas or (0.5,))[0])]
        if self.kind == "floor":
            from sofar_agents.evaluation.gamma_floor import floor_strategies
            from sofar_agents.evaluation.pareto import preference_family

            return floor_strategies(self.policy_path(root), preference_family(self.safety_weights)[0], self.floors(),
                                    self.floor_gammas)[0]
        if self.kind == "pareto":
            from sofar_agents.evaluation.pareto import pareto_strategies, preference_family

            return pareto_strategies(self.policy_path(root) if self.adaptive else None,
                                     preference_family(self.safety_weights),
                                     FIXED_GAMMAS if self.gammas is None else self.gammas)
        default = {"table2": (0.5,), "figures": ()}.get(self.kind, FIXED_GAMMAS)
        gammas = default if self.gammas is None else self.gammas
        policy = self.policy_path(root) if self.adaptive else None
        out = build_strategies(gammas, policy=policy, adaptive=self.adaptive)
        if self.self_play:
            if self.kind != "multi-agent":
                raise ValueError(f"manifest {self.name}: self_play is a key of the multi-agent table")
            out.append(Strategy.adaptive(Path(root) / self.self_play, name="self-play"))
        return out


def manifest_paths(folder: str | os.PathLike) -> list[Path]:
    """The manifests of ``folder`` (``*.toml``), sorted by name."""
    return sorted(Path(folder).glob("*.toml"))


def load_manifest(path: str | os.PathLike) -> Manifest:
    """Read and check ``path``; ``ValueError`` naming the file for an unknown key or a wrong value."""
    p = Path(path)
    data = _toml_load(p)
    names = {f.name for f in dataclasses.fields(Manifest)} - {"name"}
    unknown = sorted(set(data) - names)
    if unknown:
        raise ValueError(f"{p}: unknown keys {unknown}; valid keys: {', '.join(sorted(names))}")
    for key in _TUPLES:
        if key in data:
            data[key] = tuple(data[key])
    for key in ("kind", "out"):
        if key not in data:
            raise ValueError(f"{p}: the key {key!r} is required")
    try:
        return Manifest(name=p.stem, **data)
    except (TypeError, ValueError) as err:
        raise ValueError(f"{p}: {err}") from err
