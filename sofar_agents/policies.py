"""Deployable gamma policies: trained PASTA checkpoints, fixed gamma, SB3 PPO.

Every policy is a callable ``policy(obs) -> np.ndarray`` of shape ``(1,)`` (float32)
holding the barrier decay gamma in ``[0.05, 1]`` for a single observation of shape
``(obs_dim,)``; a batch ``(n, obs_dim)`` gives ``(n, 1)``.

PASTA checkpoints (``<stem>.json`` + ``<stem>.pt``, format described in
:mod:`sofar_agents.pasta.checkpoint`) are written by :meth:`sofar_agents.PASTA.save`.

:func:`load_policy` runs the actor's mean network in numpy (no torch call per
step), with the preference part of the first layer folded into its bias.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from sofar_agents.pasta.checkpoint import (
    FORMAT_VERSION,
    checkpoint_paths,
    read_actor_layers,
    read_checkpoint_metadata,
    validate_actor_state,
)
from sofar_agents.pasta.config import SQUASHINGS
from sofar_env.configs.registry import DEFAULT_STACK_PRESET
from sofar_env.constants import GAMMA_MAX, GAMMA_MIN

# FORMAT_VERSION, checkpoint_paths, read_checkpoint_metadata and validate_actor_state are
# re-exported from sofar_agents.pasta.checkpoint, the one module that owns the format.
__all__ = [
    "FORMAT_VERSION",
    "GAMMA_LOW",
    "GAMMA_HIGH",
    "PASTAPolicy",
    "FixedGammaPolicy",
    "SB3Policy",
    "load_policy",
    "default_policy_path",
    "named_policy_path",
    "NAMED_POLICIES",
    "checkpoint_paths",
    "read_checkpoint_metadata",
    "validate_actor_state",
]

GAMMA_LOW = GAMMA_MIN
"""Smallest barrier decay gamma (paper section V-A): the default lower bound of the policies."""
GAMMA_HIGH = GAMMA_MAX
"""Largest barrier decay gamma: the default upper bound of the policies."""


class PASTAPolicy:
    """Deterministic PASTA actor evaluated in numpy (float32).

    ``gamma = low + (high - low) * sigmoid(mean_net([obs, w]))`` (``squashing="sigmoid"``),
    ``gamma = clip(mean_net([obs, w]), low, high)`` (``squashing="clip"``), the sigmoid reaching
    ``margin * (high - low)`` beyond each bound, clipped (``squashing="sigmoid-clip"``), or
    ``gamma = low * (high / low) ** sigmoid(mean_net([obs, w]))`` (``squashing="log-sigmoid"``); the
    preference part of the first layer is folded into its bias (see :meth:`set_preference`).
    """

    def __init__(self, layers: list[tuple[np.ndarray, np.ndarray]], obs_dim: int, preference: Any,
                 action_low: Any, action_high: Any, path: str | Path | None = None,
                 objective_names: Any = None, squashing: str = "sigmoid", margin: float = 0.05) -> None:
        if squashing not in SQUASHINGS:
            raise ValueError(f"squashing must be one of {SQUASHINGS}, got {squashing!r}")
        if isinstance(margin, bool) or not isinstance(margin, (int, float)) or not 0.0 < margin <= 1.0:
            raise ValueError(f"margin must lie in (0, 1], got {margin!r}")
        self.squashing = squashing
        self.obs_dim = int(obs_dim)
        self.path = Path(path) if path is not None else None
        self._where = f"{self.path}: " if self.path is not None else ""
        w0, b0 = layers[0]
        self.n_objectives = w0.shape[1] - self.obs_dim
        self.objective_names = tuple(objective_names) if objective_names is not None else None
        self._w0_obs = np.ascontiguousarray(w0[:, : self.obs_dim].T, dtype=np.float32)
        self._w0_pref = np.asarray(w0[:, self.obs_dim:], dtype=np.float32)
        self._b0 = np.asarray(b0, dtype=np.float32)
        self._rest = [(np.ascontiguousarray(w.T, dtype=np.float32), np.asarray(b, dtype=np.float32))
                      for w, b in layers[1:]]
        self.action_low = np.asarray(action_low, dtype=np.float32)
        self.action_high = np.asarray(action_high, dtype=np.float32)
        if not (np.all(np.isfinite(self.action_low)) and np.all(np.isfinite(self.action_high))
                and np.all(self.action_low < self.action_high)):
            raise ValueError(f"{self._where}action_low {action_low} and action_high {action_high} must be finite "
                             "with action_low < action_high")
        self._scale = self.action_high - self.action_low
        self._sig_low, self._sig_scale = self.action_low, self._scale
        low64, high64 = self.action_low.astype(np.float64), self.action_high.astype(np.float64)
        if squashing == "log-sigmoid":  # as the torch squashing computes them (float32 of the float64 logs)
            if not np.all(low64 > 0.0):
                raise ValueError(f"{self._where}the log-sigmoid squashing needs action_low > 0, got {action_low}")
            self._log_low = np.log(low64).astype(np.float32)
            self._log_scale = np.log(high64 / low64).astype(np.float32)
        if squashing == "sigmoid-clip":
            reach = margin * (high64 - low64)  # as the torch squashing computes its bounds
            self._sig_low = (low64 - reach).astype(np.float32)
            self._sig_scale = (high64 + reach).astype(np.float32) - self._sig_low
        self.set_preference(preference)

    def set_preference(self, preference: Any) -> None:
        """Change the preference w (normalised to sum 1) and refresh the cached bias."""
        try:
            w = np.asarray(preference, dtype=np.float64).reshape(-1)
        except (TypeError, ValueError) as err:
            raise ValueError(f"{self._where}preference must be {self.n_objectives} numbers, "
                             f"got {preference!r}") from err
        if (w.shape != (self.n_objectives,) or not np.all(np.isfinite(w)) or np.any(w < 0)
                or not (np.isfinite(w.sum()) and w.sum() > 0)):
            raise ValueError(f"{self._where}preference must be {self.n_objectives} finite non-negative weights "
                             f"with a positive sum, got {preference}")
        self.preference = (w / w.sum()).astype(np.float32)
        self._b0_eff = (self._b0 + self._w0_pref @ self.preference).astype(np.float32)

    def __call__(self, obs: Any) -> np.ndarray:
        x = np.asarray(obs, dtype=np.float32)
        if x.shape[-1:] != (self.obs_dim,) or x.ndim > 2:
            raise ValueError(f"expected an observation of shape ({self.obs_dim},) or (n, {self.obs_dim}), "
                             f"got {x.shape} (a policy of the paper world's 12 values runs in the interactive "
                             f"world with observation='paper')")
        h = np.tanh(x @ self._w0_obs + self._b0_eff)
        for w, b in self._rest[:-1]:
            h = np.tanh(h @ w + b)
        w, b = self._rest[-1]
        out = h @ w + b
        if self.squashing == "clip":
            gamma = out
        elif self.squashing == "log-sigmoid":
            gamma = np.exp(self._log_low + self._log_scale / (1.0 + np.exp(-out)))
        else:
            gamma = self._sig_low + self._sig_scale / (1.0 + np.exp(-out))
        return np.clip(gamma, self.action_low, self.action_high).astype(np.float32, copy=False)

    def __repr__(self) -> str:
        weights = ", ".join(f"{float(w):.6g}" for w in self.preference)  # float32 weights as written: 0.31
        return f"PASTAPolicy(path={str(self.path)!r}, preference=[{weights}])"


def load_policy(path: str | Path, preference: Any = None, obs_dim: int | None = None) -> PASTAPolicy:
    """Load a PASTA checkpoint as a fast deterministic gamma policy.

    Args:
        path: ``stem``, ``stem.json`` or ``stem.pt`` of a checkpoint written by
            :meth:`sofar_agents.PASTA.save`, or the name of a shipped policy (:data:`NAMED_POLICIES`).
        preference: override of the deployment preference stored in the JSON.
        obs_dim: expected observation size; a checkpoint for another size raises
            ``ValueError``.

    Raises:
        FileNotFoundError: a checkpoint file is missing.
        ValueError: wrong format version, observation size or tensor shapes, NaN/inf
            weights, any JSON field of the wrong type or out of range (action bounds outside
            the gamma range [0.05, 1] or inverted, a preference of the wrong length or
            without a positive finite sum, ...), or a tensor file that is not the one the
            JSON was written with (the message names the file and the field).
    """
    meta, json_path, pt_path = read_checkpoint_metadata(named_policy_path(path) if str(path) in NAMED_POLICIES
                                                        else path)
    if obs_dim is not None and meta["obs_dim"] != obs_dim:
        raise ValueError(f"{json_path}: checkpoint expects observations of size {meta['obs_dim']}, "
                         f"not {obs_dim}")
    layers = read_actor_layers(meta, pt_path, json_path)
    return PASTAPolicy(layers, meta["obs_dim"], meta["preference"] if preference is None else preference,
                       meta["action_low"], meta["action_high"], path=json_path,
                       objective_names=meta.get("objective_names"),
                       squashing=meta.get("action_squashing", "sigmoid"),
                       margin=meta["config"].get("squash_margin", 0.05))


SHIPPED_POLICIES: dict[tuple[str, str], str] = {
    ("sofar-17", "paper"): "pasta_lagunaseca_sofar17.json",
    ("sofar-17", "interactive"): "pasta_lagunaseca_interactive_sofar17.json",
    ("sofar-17", "interactive-2"): "pasta_lagunaseca_interactive2_sofar17.json",
    ("sofar-13", "paper"): "pasta_lagunaseca_sofar13.json",
    ("sofar-13", "interactive"): "pasta_lagunaseca_interactive_sofar13.json",
    ("sofar-6", "paper"): "pasta_lagunaseca_sofar6.json",
    ("sofar-6", "interactive"): "pasta_lagunaseca_interactive_sofar6.json",
    ("sofar-4", "paper"): "pasta_lagunaseca_sofar4.json",
    ("sofar-4", "interactive"): "pasta_lagunaseca_interactive_sofar4.json",
    ("sofar-1", "paper"): "pasta_lagunaseca.json",
    ("sofar-1", "interactive"): "pasta_lagunaseca_interactive.json",
    ("paper", "paper"): "pasta_lagunaseca_paper.json",
}
"""The shipped PASTA policies, by (controller preset they were trained with, world scenario): all trained on
Laguna Seca only; ``"sofar"`` looks up the default controller's version (``"sofar-17"``). The interactive ones
were trained with a field of 8 opponents (``n_opponents=8``), the dense field of the interactive world, and observe
the interactive world's 16 values; ``"interactive"`` is the world of the ``-Interactive-v0`` ids, ``"interactive-2"``
that of the ``-Interactive-v1`` ids (the same recipe and training seed in the world without the squeeze deadlock).
The ``"sofar-13"``, ``"sofar-6"``, ``"sofar-4"`` and ``"sofar-1"`` ones were
trained with the former defaults and made their tables, by the same recipes."""


NAMED_POLICIES: dict[str, str] = {
    "lagunaseca": "pasta_lagunaseca.json",
    "lagunaseca-sofar-17": "pasta_lagunaseca_sofar17.json",
    "lagunaseca-sofar-13": "pasta_lagunaseca_sofar13.json",
    "lagunaseca-sofar-6": "pasta_lagunaseca_sofar6.json",
    "lagunaseca-sofar-4": "pasta_lagunaseca_sofar4.json",
    "lagunaseca-paper": "pasta_lagunaseca_paper.json",
    "lagunaseca-interactive": "pasta_lagunaseca_interactive.json",
    "lagunaseca-interactive-sofar-17": "pasta_lagunaseca_interactive_sofar17.json",
    "lagunaseca-interactive-2-sofar-17": "pasta_lagunaseca_interactive2_sofar17.json",
    "lagunaseca-interactive-sofar-13": "pasta_lagunaseca_interactive_sofar13.json",
    "lagunaseca-interactive-sofar-6": "pasta_lagunaseca_interactive_sofar6.json",
    "lagunaseca-interactive-sofar-4": "pasta_lagunaseca_interactive_sofar4.json",
    "morl-dynamic": "pasta_morl_dynamic.json",
    "morl-dynamic-sofar-17": "pasta_morl_dynamic_sofar17_circuits_seed82.json",
    "morl-dynamic-sofar-13": "pasta_morl_dynamic_sofar13.json",
    "morl-dynamic-sofar-13-sigmoid": "pasta_morl_dynamic_sofar13_sigmoid.json",
    "morl-dynamic-sofar-6": "pasta_morl_dynamic_sofar6.json",
    "morl-dynamic-sofar-4": "pasta_morl_dynamic_sofar4.json",
    "morl-interactive-sofar-17": "pasta_morl_interactive_sofar17_sigmoid_seed91.json",
    "morl-interactive-2-sofar-17": "pasta_morl_interactive2_sofar17_sigmoid_seed91.json",
    "morl-dynamic-2-sofar-17": "pasta_morl_dynamic2_sofar17_circuits_seed82.json",
    "morl-interactive-sofar-13": "pasta_morl_interactive_sofar13.json",
    "morl-interactive-sofar-13-sigmoid": "pasta_morl_interactive_sofar13_sigmoid.json",
    "morl-interactive-sofar-6": "pasta_morl_interactive_sofar6.json",
    "morl-interactive-sofar-4": "pasta_morl_interactive_sofar4.json",
}
"""The shipped PASTA policies by name (:func:`named_policy_path`, :func:`load_policy`). ``lagunaseca`` and
``lagunaseca-interactive``: trained with ``"sofar-1"``, the first default; ``lagunaseca-sofar-4`` and
``lagunaseca-interactive-sofar-4``: the same recipes with ``"sofar-4"``, the second; ``lagunaseca-sofar-6`` and
``lagunaseca-interactive-sofar-6``: with ``"sofar-6"``, the third; ``lagunaseca-sofar-13`` and
``lagunaseca-interactive-sofar-13``: with ``"sofar-13"``, the fourth; ``lagunaseca-sofar-17`` and
``lagunaseca-interactive-sofar-17``: the same recipes with the default controller;
``lagunaseca-interactive-2-sofar-17``: the interactive recipe with the default controller in the world of the
``-Interactive-v1`` ids. ``morl-dynamic-sofar-6`` and ``morl-interactive-sofar-6``: the preference-conditioned
policies of the dynamic and the dense interactive world (8 opponents), trained with ``"sofar-6"`` (the default
before ``"sofar-13"``) on Laguna Seca, started at the cautious end of the gamma range with a preference drawn every
64 decisions along the safety-overtakes path (``preference_sampling="trade-off"``); ``morl-dynamic-sofar-4`` and
``morl-interactive-sofar-4``: the same recipes with ``"sofar-4"``; ``morl-dynamic-sofar-13`` and
``morl-interactive-sofar-13``: with ``"sofar-13"`` (the default before ``"sofar-17"``; fronts:
``results/interactive_dense/morl_sofar13/``, ``results/dynamic/morl_sofar13/``);
``morl-interactive-sofar-13-sigmoid`` and ``morl-dynamic-sofar-13-sigmoid``: the same recipes with the action
squashed by a sigmoid instead of clipped and GAE lambda 0.99: faster at every preference than the clipped ones,
weaker at the cautious end (``docs/decisions/pasta-preference.md``,
``results/interactive_dense/morl_sofar13/sigmoid/``, ``results/dynamic/morl_sofar13/sigmoid/``);
``morl-interactive-sofar-17``: the dense sigmoid recipe with the default controller (training seed 91;
``results/interactive_dense/morl_sofar17/``); ``morl-dynamic-sofar-17``: the dynamic sigmoid recipe with the default
controller, trained on all four circuits (``train/pasta.py --circuits``, training seed 82;
``results/dynamic/morl_sofar17/``). ``morl-interactive-2-sofar-17`` and ``morl-dynamic-2-sofar-17``: the same two
recipes and training seeds re-trained in the world of the ``-v1`` ids (``scenario="interactive-2"``,
``"dynamic-2"``; fronts: ``results/interactive_dense/morl_sofar17_v1/``, ``results/dynamic/morl_sofar17_v1/``).
Their gamma falls as the safety weight grows (``tests/agents/test_policies.py``,
``docs/decisions/pasta-preference.md``). ``morl-dynamic``: the dynamic world's first such policy, trained with
``"sofar-1"`` from the middle of the range."""


def named_policy_path(name: str) -> Path:
    """Path of the shipped policy called ``name`` (:data:`NAMED_POLICIES`); ``KeyError`` naming the valid names."""
    from importlib.resources import files

    if name not in NAMED_POLICIES:
        raise KeyError(f"no shipped policy called {name!r}; shipped: {', '.join(NAMED_POLICIES)}")
    return Path(str(files("sofar_agents") / "checkpoints" / NAMED_POLICIES[name]))


def default_policy_path(stack: str = "sofar", scenario: str = "paper") -> Path:
    """Path of the PASTA policy shipped for a controller preset and a world (trained on Laguna Seca).

    ``stack="sofar"`` (default) or ``"sofar-17"``: trained with the default controller; ``stack="sofar-13"``,
    ``"sofar-6"``, ``"sofar-4"`` and ``"sofar-1"``: trained with the defaults before it; ``stack="paper"``: trained
    with the paper's Algorithm 1 as written (``gym.make(..., stack="paper")``). Raises ``ValueError`` for a
    combination without a shipped policy and ``FileNotFoundError`` (with instructions) when its files are missing.
    """
    from importlib.resources import files

    key = (str(stack).strip().lower(), str(scenario).strip().lower())
    if key[0] == "sofar":  # the default controller, by its version
        key = (DEFAULT_STACK_PRESET, key[1])
    if key not in SHIPPED_POLICIES:
        have = ", ".join(f"stack={a!r}, scenario={b!r}" for a, b in SHIPPED_POLICIES)
        raise ValueError(f"no shipped PASTA policy for stack={stack!r}, scenario={scenario!r}; shipped: {have}")
    name = SHIPPED_POLICIES[key]
    path = Path(str(files("sofar_agents") / "checkpoints" / name))
    if not path.is_file():
        raise FileNotFoundError(
            f"no packaged PASTA policy at {path}. Train one with "
            "`python train/pasta.py --out runs/pasta` and copy runs/pasta/pasta_final.json and "
            f"runs/pasta/pasta_final.pt to sofar_agents/checkpoints/ as {name} and "
            f"{name[:-5]}.pt (keep the 'weights_file' entry of the JSON in step), or use "
            "FixedGammaPolicy(0.5) for a fixed-gamma controller"
        )
    return path


class FixedGammaPolicy:
    """Constant gamma, with the same callable interface as the learned policies."""

    def __init__(self, gamma: float = 0.5, low: float = GAMMA_LOW, high: float = GAMMA_HIGH) -> None:
        gamma = float(gamma)
        if not (np.isfinite(gamma) and low <= gamma <= high):
            raise ValueError(f"gamma must lie in [{low}, {high}], got {gamma}")
        self.gamma = gamma
        self._out = np.array([gamma], dtype=np.float32)

    def __call__(self, obs: Any = None) -> np.ndarray:
        if obs is not None and np.ndim(obs) == 2:
            return np.full((np.shape(obs)[0], 1), self.gamma, dtype=np.float32)
        return self._out.copy()

    def __repr__(self) -> str:
        return f"FixedGammaPolicy({self.gamma})"


class SB3Policy:
    """A Stable-Baselines3 PPO zip (see ``train/ppo.py``) as a gamma policy.

    A model whose action space is ``[-1, 1]`` (trained behind
    :class:`sofar_agents.wrappers.RescaleGammaAction`) is mapped affinely to
    ``[low, high]``; a model acting directly in gamma units is only clipped.
    """

    def __init__(self, path: str | Path, low: float = GAMMA_LOW, high: float = GAMMA_HIGH) -> None:
        from stable_baselines3 import PPO

        self.path = Path(path)
        self.model = PPO.load(self.path, device="cpu")
        self.low, self.high = float(low), float(high)
        space = self.model.action_space
        self._rescale = bool(np.allclose(space.low, -1.0) and np.allclose(space.high, 1.0))
        self.obs_dim = int(np.prod(self.model.observation_space.shape))

    def __call__(self, obs: Any) -> np.ndarray:
        x = np.asarray(obs, dtype=np.float32)
        action, _ = self.model.predict(x, deterministic=True)
        a = np.asarray(action, dtype=np.float32)
        if self._rescale:
            a = self.low + (np.clip(a, -1.0, 1.0) + 1.0) * 0.5 * (self.high - self.low)
        a = np.clip(a, self.low, self.high).astype(np.float32)
        return a.reshape(-1) if x.ndim == 1 else a.reshape(x.shape[0], -1)

    def __repr__(self) -> str:
        return f"SB3Policy({str(self.path)!r})"
