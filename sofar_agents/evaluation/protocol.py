"""The paper's evaluation protocol: strategies, episodes and their paired seeds.

Protocol (paper section V)
--------------------------
* A **strategy** chooses gamma every control step: the adaptive policy
  (``load_policy``), a fixed gamma, or a Stable-Baselines3 PPO policy.
* An **episode** is one reset of ``SOfAR-<Track>-v0`` at pace ratio ``rho``,
  run until a collision or leaving the track (failure) or the horizon
  (``duration``, 200 s in the paper; success).
* **Paired seeds**: episode ``e`` of ``(track, rho)`` is reset with
  :func:`episode_seed` ``(base_seed, track, rho, e)``, which does not depend on
  the strategy nor on the MIQP setting, so every strategy starts from the same
  randomised ego state and opponent field.

This module describes *what* to run (:class:`Strategy`, :class:`EpisodeTask`, the
task lists of Tables I and II); it runs nothing. An episode's resume key
(:attr:`EpisodeTask.key`) holds every setting that changes the episode, including the hash of the resolved
configuration (:attr:`EpisodeTask.config_hash`), so that a default that moves makes new episodes instead of
reusing rows of the old configuration.
"""

from __future__ import annotations

import os
import warnings
import zlib
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from sofar_agents.evaluation.files import content_id
from sofar_env.constants import CIRCUIT_ABBREVIATIONS, EPISODE_SECONDS, TABLE_ORDER
from sofar_env.constants import FIXED_GAMMAS as _FIXED_GAMMAS
from sofar_env.constants import RHOS as _RHOS

TRACKS: tuple[str, ...] = TABLE_ORDER
"""The four circuits of the paper, in the paper's table order."""
TRACK_ABBREVIATIONS = CIRCUIT_ABBREVIATIONS
RHOS: tuple[float, ...] = _RHOS
"""Opponent pace ratios of the paper."""
FIXED_GAMMAS: tuple[float, ...] = _FIXED_GAMMAS
"""Fixed barrier decays of the paper's baselines."""
DEFAULT_DURATION = EPISODE_SECONDS
"""Episode horizon of the paper [s]."""


@dataclass(frozen=True)
class Strategy:
    """How gamma is chosen: ``kind`` is ``"fixed"`` (``gamma``), ``"policy"`` or ``"sb3"`` (``path``)."""

    name: str
    """Label in the CSV, e.g. ``adaptive``, ``gamma=0.05``, ``sb3``; part of the resume key, so it must tell apart
    every setting that changes an episode (a fixed gamma's name holds :func:`gamma_text` of its gamma)."""
    kind: str
    gamma: float | None = None
    path: str | None = None
    policy_id: str = ""
    """Short content hash of the policy file ("" for fixed gammas); part of the resume key."""
    preference: tuple[float, ...] | None = None
    """Preference given to a PASTA policy instead of its stored deployment preference (None: the stored one).
    A strategy with its own preference needs its own ``name`` (the name is part of the resume key)."""

    def __post_init__(self) -> None:
        if self.kind not in ("fixed", "policy", "sb3"):
            raise ValueError(f"unknown strategy kind {self.kind!r}")
        if self.kind == "fixed" and (self.gamma is None or not (0.0 < self.gamma <= 1.0)):
            raise ValueError(f"a fixed strategy needs gamma in (0, 1], got {self.gamma!r}")
        if self.kind != "fixed" and not self.path:
            raise ValueError(f"a {self.kind} strategy needs a path")
        if self.preference is not None and self.kind != "policy":
            raise ValueError("only a policy strategy takes a preference")

    @classmethod
    def fixed(cls, gamma: float) -> Strategy:
        """The fixed ``gamma``, named ``gamma=<gamma_text(gamma)>``: two fixed strategies share a name (and so
        their resume key and CSV rows) only if their gammas are the same float."""
        return cls(name=f"gamma={gamma_text(gamma)}", kind="fixed", gamma=float(gamma))

    @classmethod
    def adaptive(cls, path: str | os.PathLike, name: str = "adaptive",
                 preference: Sequence[float] | None = None) -> Strategy:
        """A PASTA checkpoint (``stem``, ``stem.json`` or ``stem.pt``); its id hashes the JSON and the weights.
        ``preference``: run it at this preference instead of its stored one (checked against the checkpoint)."""
        from sofar_agents.policies import load_policy, read_checkpoint_metadata

        _, json_path, pt_path = read_checkpoint_metadata(path)
        if preference is not None:
            preference = tuple(float(w) for w in preference)
            load_policy(json_path, preference=preference)  # raises now for a preference the policy cannot take
        return cls(name=name, kind="policy", path=str(json_path), policy_id=content_id(json_path, pt_path),
                   preference=preference)

    @classmethod
    def sb3(cls, path: str | os.PathLike, name: str = "sb3") -> Strategy:
        return cls(name=name, kind="sb3", path=str(path), policy_id=content_id(path))

    @property
    def label(self) -> str:
        """Display name in the Markdown tables."""
        if self.kind == "fixed":
            return f"γ = {gamma_text(self.gamma)}"
        if self.kind == "sb3":
            return "PPO (SB3)"
        return "Adaptive" if self.name == "adaptive" else self.name

    def build(self) -> Callable[[Any], np.ndarray]:
        """The callable obs -> gamma array of shape (1,)."""
        if self.kind == "fixed":
            from sofar_agents import FixedGammaPolicy

            return FixedGammaPolicy(self.gamma)
        _limit_torch_threads()
        if self.kind == "sb3":
            from sofar_agents.policies import SB3Policy

            return SB3Policy(self.path)
        from sofar_agents import load_policy

        return load_policy(self.path, preference=self.preference)


def gamma_text(gamma: float) -> str:
    """``gamma`` as text that reads back to the same float: two decimals when they hold it exactly (``0.05``,
    ``0.30``: the names of the rows already in the result files), else the shortest text that does (``0.054``,
    ``0.075``; Python's ``repr``). Two gammas give the same text only if they are the same float."""
    g = float(gamma)
    two = f"{g:.2f}"
    return two if float(two) == g else repr(g)


def _limit_torch_threads() -> None:
    """One intra-op thread: the networks are tiny and the workers already use every core."""
    try:
        import torch

        torch.set_num_threads(1)
    except Exception:  # pragma: no cover - torch is a dependency, but timing code must not fail on it
        pass


def exact_text(x: float) -> str:
    """``x`` as short text that reads back to the same float: ``{x:g}`` when it does (``0.3``, ``200``: the
    values in the result files), else the shortest text that does (Python's ``repr``). The resume keys hold
    their floats in this form, so two settings share a key only if they are the same float."""
    x = float(x)
    short = f"{x:g}"
    return short if float(short) == x else repr(x)


_fmt_float = exact_text


@dataclass(frozen=True)
class EpisodeTask:
    """One episode to run."""

    track: str
    strategy: Strategy
    rho: float
    episode: int
    seed: int
    use_miqp: bool = True
    duration: float = DEFAULT_DURATION
    """Episode horizon [s]; reaching it without a collision or leaving the track is a success."""
    n_opponents: int | None = None
    """Opponent count (None: the environment's default, 4)."""
    stack: str = "sofar"
    """Controller preset (``"sofar"`` or ``"paper"``, see :func:`sofar_env.stack.stack_preset`)."""
    scenario: str = "paper"
    """World (``"paper"``, ``"interactive"`` or ``"dynamic"``, see :mod:`sofar_env.scenarios`)."""
    trace: bool = False
    """Record a per-step trace (gamma, nearest opponent, smallest barrier value)."""
    pinned_hash: str | None = None
    """A configuration hash given instead of the resolved one (``""``: the rows written before the hash);
    None (the default): :attr:`config_hash` is resolved from ``stack``, ``scenario`` and ``duration``."""

    @property
    def config_hash(self) -> str:
        """:func:`sofar_env.config_hash.config_hash` of the episode's resolved configuration (controller, world,
        duration; not the circuit, rho or the MIQP switch:
        :func:`~sofar_agents.evaluation.configs.episode_config_hash`), or :attr:`pinned_hash`. Part of the
        resume key; the episode runner checks it against the environment it runs."""
        if self.pinned_hash is not None:
            return self.pinned_hash
        from sofar_agents.evaluation.configs import episode_config_hash

        return episode_config_hash(self.stack, self.scenario, self.duration)

    @property
    def key(self) -> tuple:
        return _key(self.track, self.strategy.name, self.strategy.policy_id, self.rho, self.seed, self.use_miqp,
                    self.duration, self.stack, self.n_opponents, self.scenario, self.config_hash)

    @property
    def env_key(self) -> tuple:
        return (self.track, bool(self.use_miqp), float(self.duration), self.stack, self.scenario)


LEGACY_STACK = "sofar-1"
"""The controller of a row without a ``stack`` value: made before the column existed, by the default of that
time, the controller now named ``"sofar-1"`` (rows never default to ``"sofar"``, whose meaning moves with the
default)."""


def _key(track, strategy, policy_id, rho, seed, use_miqp, duration, stack, n_opponents, scenario="paper",
         config_hash="") -> tuple:
    """The resume key: every setting that changes an episode (rows of older files: stack :data:`LEGACY_STACK`, the
    default opponent count, config hash "": none, which no task of this version has)."""
    n_opp = "" if n_opponents in (None, "") else str(int(float(n_opponents)))
    return (str(track), str(strategy), str(policy_id or ""), _fmt_float(rho), int(seed), bool(use_miqp),
            _fmt_float(duration), str(stack or LEGACY_STACK), n_opp, str(scenario or "paper"), str(config_hash or ""))


def episode_seed(base_seed: int, track: str, rho: float, episode: int) -> int:
    """The reset seed of episode ``episode`` of ``(track, rho)``: the same for every strategy.

    Derived with :class:`numpy.random.SeedSequence` from the base seed, a CRC32 of the
    track name, rho in micro-units and the episode index: deterministic across
    processes, platforms and Python hash randomisation.
    """
    entropy = [int(base_seed) & 0xFFFFFFFF, zlib.crc32(str(track).encode("utf-8")),
               int(round(float(rho) * 1_000_000)), int(episode)]
    return int(np.random.SeedSequence(entropy).generate_state(1, np.uint32)[0])


def resolve_policy_path(path: str | os.PathLike | None = None,
                        fallback: str = "the Adaptive row is skipped", stack: str = "sofar",
                        scenario: str = "paper") -> Path | None:
    """``path`` if given (must exist), else the policy shipped for ``stack`` / ``scenario`` if it exists, else None.

    A missing shipped policy gives a warning that ends with ``fallback`` (what happens instead).
    """
    if path is not None:
        p = Path(path)
        if not p.exists() and not p.with_name(p.name + ".json").exists():
            raise FileNotFoundError(f"policy file not found: {p}")
        return p
    try:
        from sofar_agents import default_policy_path

        p = default_policy_path(stack=stack, scenario=scenario)
    except Exception as exc:  # missing checkpoint may raise
        warnings.warn(f"no shipped adaptive policy: {exc}. So {fallback}.", stacklevel=2)
        return None
    if p is None or not Path(p).exists():
        warnings.warn(f"the shipped adaptive policy {p} is missing (train one with train/pasta.py or pass "
                      f"--policy PATH). So {fallback}.", stacklevel=2)
        return None
    return Path(p)


def build_strategies(gammas: Sequence[float] = FIXED_GAMMAS, policy: str | os.PathLike | None = None,
                     sb3: str | os.PathLike | None = None, adaptive: bool = True) -> list[Strategy]:
    """Adaptive (``policy`` or the shipped one, when present), the fixed gammas, then SB3 PPO if given."""
    out: list[Strategy] = []
    if adaptive:
        p = resolve_policy_path(policy)
        if p is not None:
            out.append(Strategy.adaptive(p))
    out.extend(Strategy.fixed(g) for g in gammas)
    if sb3 is not None:
        if not Path(sb3).exists():
            raise FileNotFoundError(f"SB3 policy file not found: {sb3}")
        out.append(Strategy.sb3(sb3))
    names = [s.name for s in out]
    if len(set(names)) != len(names):
        raise ValueError(f"duplicate strategies: {names}")
    return out


def table1_tasks(strategies: Sequence[Strategy], tracks: Sequence[str] = TRACKS, rhos: Sequence[float] = RHOS,
                 episodes: int = 5, base_seed: int = 0, duration: float = DEFAULT_DURATION,
                 trace: bool | Callable[[Strategy], bool] = False, stack: str = "sofar",
                 scenario: str = "paper", n_opponents: int | None = None) -> list[EpisodeTask]:
    """Every (track, rho, episode, strategy) of Table I, grouped by track so workers reuse environments
    (``n_opponents``: the field size, None for the environment's default of 4)."""
    tasks = []
    for track in tracks:
        for rho in rhos:
            for e in range(episodes):
                seed = episode_seed(base_seed, track, rho, e)
                for strat in strategies:
                    tr = trace(strat) if callable(trace) else bool(trace)
                    tasks.append(EpisodeTask(track, strat, float(rho), e, seed, True, float(duration),
                                             n_opponents=n_opponents, stack=stack, scenario=scenario, trace=tr))
    return tasks


def miqp_ablation_tasks(strategies: Sequence[Strategy], episodes: int = 10, rhos: Sequence[float] = RHOS,
                        track: str = "LagunaSeca", base_seed: int = 0,
                        duration: float = DEFAULT_DURATION, stack: str = "sofar",
                        scenario: str = "paper") -> list[EpisodeTask]:
    """Table II: ``episodes`` episodes per (MIQP setting, strategy), rho cycling over ``rhos``.

    Episode ``k`` runs at ``rhos[k % len(rhos)]`` with the seed of episode ``k // len(rhos)``
    of that rho, so it pairs with Table I's episodes and across both settings.
    """
    tasks = []
    for use_miqp in (False, True):
        for k in range(episodes):
            rho = float(rhos[k % len(rhos)])
            e = k // len(rhos)
            seed = episode_seed(base_seed, track, rho, e)
            for strat in strategies:
                tasks.append(EpisodeTask(track, strat, rho, e, seed, use_miqp, float(duration), stack=stack,
                                         scenario=scenario))
    return tasks


FULL_TABLE1_STEPS = len(TRACKS) * len(RHOS) * 5 * (1 + len(FIXED_GAMMAS)) * int(DEFAULT_DURATION / 0.1)
"""Control steps of a full Table I if every episode lasted 200 s (700 episodes x 2000 = 1.4 M)."""


def ended_tasks(rows: Iterable[Mapping], outcome: str, stacks: Sequence[str] | None = None) -> list[EpisodeTask]:
    """The fixed-gamma episodes of per-episode CSV rows (typed, ``read_episode_csv``) whose ``outcome`` column
    (``"stalled"``, ``"off_track"``, ...) is true, as tasks to replay; only those of ``stacks`` when given."""
    out = []
    for r in rows:
        if not r.get(outcome) or not str(r["strategy"]).startswith("gamma="):
            continue
        stack = str(r.get("stack") or LEGACY_STACK)
        if stacks is not None and stack not in stacks:
            continue
        n_opp = r.get("n_opponents", "")
        out.append(EpisodeTask(
            track=str(r["track"]), strategy=Strategy.fixed(float(str(r["strategy"])[6:])), rho=float(r["rho"]),
            episode=int(r.get("episode", 0)), seed=int(r["seed"]), use_miqp=bool(r["use_miqp"]),
            duration=float(r["duration"]), n_opponents=None if n_opp in ("", None) else int(float(n_opp)),
            stack=stack, scenario=str(r.get("scenario") or "paper")))
    return out
