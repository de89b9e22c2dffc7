"""Deployable gamma policies: trained PASTA checkpoints, fixed gamma, SB3 PPO.

Every policy is a callable ``policy(obs) -> np.ndarray`` of shape ``(1,)`` (float32)
holding the barrier decay gamma in ``[0.05, 1]`` for a single observation of shape
``(obs_dim,)``; a batch ``(n, obs_dim)`` gives ``(n, 1)``.

Checkpoint format (``format_version`` 1), written by :meth:`sofar_agents.PASTA.save`:

- ``<stem>.json``: ``format_version``, ``algorithm``, ``weights_file``, ``obs_dim``,
  ``n_objectives``, ``objective_names``, ``act_dim``, ``action_low``, ``action_high``,
  ``action_squashing`` (``"sigmoid"``: ``a = low + (high - low) * sigmoid(u)``),
  ``activation`` (``"tanh"``), the deployment ``preference``, the PASTA ``config``,
  the optimiser ``state`` counters and ``training`` metadata (command, seed, env,
  code version, steps, wall time).
- ``<stem>.pt``: ``torch.save`` of a dict of tensors / state dicts (``actor``,
  ``critic``, ``optimizer``, normaliser statistics), read with
  ``torch.load(weights_only=True)``.

:func:`load_policy` runs the actor's mean network in numpy (no torch call per
step), with the preference part of the first layer folded into its bias.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "FORMAT_VERSION",
    "GAMMA_LOW",
    "GAMMA_HIGH",
    "PASTAPolicy",
    "FixedGammaPolicy",
    "SB3Policy",
    "load_policy",
    "default_policy_path",
    "checkpoint_paths",
    "read_checkpoint_metadata",
    "validate_actor_state",
]

FORMAT_VERSION = 1
"""Version of the PASTA checkpoint format written and accepted by this package."""
GAMMA_LOW = 0.05
"""Smallest barrier decay gamma (paper section V-A)."""
GAMMA_HIGH = 1.0
"""Largest barrier decay gamma."""

_REQUIRED_KEYS = ("format_version", "obs_dim", "n_objectives", "action_low", "action_high", "preference",
                  "config")


def checkpoint_paths(path: str | Path) -> tuple[Path, Path]:
    """``(json_path, pt_path)`` for a checkpoint path given as ``stem``, ``stem.json`` or ``stem.pt``."""
    p = Path(path)
    stem = p.with_suffix("") if p.suffix in (".json", ".pt") else p
    return Path(f"{stem}.json"), Path(f"{stem}.pt")


def read_checkpoint_metadata(path: str | Path) -> tuple[dict[str, Any], Path, Path]:
    """Read and validate the JSON half of a checkpoint.

    Returns ``(metadata, json_path, pt_path)``. Raises ``FileNotFoundError`` when a
    file is missing and ``ValueError`` (naming the file) for a wrong format version
    or inconsistent fields.
    """
    json_path, pt_path = checkpoint_paths(path)
    if not json_path.is_file():
        raise FileNotFoundError(f"checkpoint metadata {json_path} not found")
    try:
        meta = json.loads(json_path.read_text())
    except json.JSONDecodeError as err:
        raise ValueError(f"{json_path}: not a valid JSON checkpoint ({err})") from err
    if not isinstance(meta, dict):
        raise ValueError(f"{json_path}: expected a JSON object")
    missing = [k for k in _REQUIRED_KEYS if k not in meta]
    if missing:
        raise ValueError(f"{json_path}: not a PASTA checkpoint, missing keys {missing}")
    if meta["format_version"] != FORMAT_VERSION:
        raise ValueError(
            f"{json_path}: checkpoint format_version {meta['format_version']!r} is not supported "
            f"(this version of sofar_agents reads format_version {FORMAT_VERSION})"
        )
    k = meta["n_objectives"]
    if len(meta["preference"]) != k:
        raise ValueError(f"{json_path}: preference has {len(meta['preference'])} entries for {k} objectives")
    if "objective_names" in meta and len(meta["objective_names"]) != k:
        raise ValueError(f"{json_path}: {len(meta['objective_names'])} objective names for {k} objectives")
    if len(meta["action_low"]) != len(meta["action_high"]):
        raise ValueError(f"{json_path}: action_low and action_high differ in length")
    if meta.get("action_squashing", "sigmoid") != "sigmoid" or meta.get("activation", "tanh") != "tanh":
        raise ValueError(f"{json_path}: unsupported squashing/activation "
                         f"{meta.get('action_squashing')!r}/{meta.get('activation')!r}")
    if "weights_file" in meta:
        pt_path = json_path.parent / meta["weights_file"]
    if not pt_path.is_file():
        raise FileNotFoundError(f"checkpoint weights {pt_path} (referenced by {json_path}) not found")
    return meta, json_path, pt_path


def _actor_layers(actor_state: dict[str, np.ndarray], pt_path: Path) -> list[tuple[np.ndarray, np.ndarray]]:
    idx = sorted({int(m.group(1)) for key in actor_state if (m := re.fullmatch(r"mean_net\.(\d+)\.weight", key))})
    if not idx:
        raise ValueError(f"{pt_path}: no actor layers 'mean_net.<i>.weight' in the state dict")
    layers = []
    for i in idx:
        w, b = actor_state[f"mean_net.{i}.weight"], actor_state.get(f"mean_net.{i}.bias")
        if b is None or w.ndim != 2 or b.shape != (w.shape[0],):
            raise ValueError(f"{pt_path}: malformed actor layer {i}: weight {w.shape}, bias "
                             f"{None if b is None else b.shape}")
        layers.append((w, b))
    return layers


def validate_actor_state(actor_state: dict[str, np.ndarray], meta: dict[str, Any], pt_path: Path) -> list:
    """Check the actor's tensor shapes against the metadata; return its linear layers."""
    layers = _actor_layers(actor_state, pt_path)
    obs_dim, k, act_dim = meta["obs_dim"], meta["n_objectives"], len(meta["action_low"])
    in_dim = layers[0][0].shape[1]
    if in_dim != obs_dim + k:
        raise ValueError(
            f"{pt_path}: actor input has {in_dim} features but the metadata says obs_dim {obs_dim} "
            f"+ {k} preference weights = {obs_dim + k}"
        )
    for n, ((w_prev, _), (w, _)) in enumerate(zip(layers, layers[1:])):
        if w.shape[1] != w_prev.shape[0]:
            raise ValueError(f"{pt_path}: actor layer {n + 1} expects {w.shape[1]} inputs, "
                             f"previous layer gives {w_prev.shape[0]}")
    if layers[-1][0].shape[0] != act_dim:
        raise ValueError(f"{pt_path}: actor outputs {layers[-1][0].shape[0]} values, action has {act_dim}")
    hidden = [w.shape[0] for w, _ in layers[:-1]]
    cfg_hidden = list(meta["config"].get("hidden_sizes", hidden))
    if hidden != cfg_hidden:
        raise ValueError(f"{pt_path}: actor hidden sizes {hidden} differ from the config's {cfg_hidden}")
    return layers


class PASTAPolicy:
    """Deterministic PASTA actor evaluated in numpy (float32).

    ``gamma = low + (high - low) * sigmoid(mean_net([obs, w]))``; the preference
    part of the first layer is folded into its bias (see :meth:`set_preference`).
    """

    def __init__(self, layers: list[tuple[np.ndarray, np.ndarray]], obs_dim: int, preference: Any,
                 action_low: Any, action_high: Any, path: str | Path | None = None,
                 objective_names: Any = None) -> None:
        self.obs_dim = int(obs_dim)
        self.path = Path(path) if path is not None else None
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
        self._scale = self.action_high - self.action_low
        self.set_preference(preference)

    def set_preference(self, preference: Any) -> None:
        """Change the preference w (normalised to sum 1) and refresh the cached bias."""
        w = np.asarray(preference, dtype=np.float64).reshape(-1)
        if w.shape != (self.n_objectives,) or np.any(w < 0) or w.sum() <= 0:
            raise ValueError(f"preference must be {self.n_objectives} non-negative weights, got {preference}")
        self.preference = (w / w.sum()).astype(np.float32)
        self._b0_eff = (self._b0 + self._w0_pref @ self.preference).astype(np.float32)

    def __call__(self, obs: Any) -> np.ndarray:
        x = np.asarray(obs, dtype=np.float32)
        if x.shape[-1:] != (self.obs_dim,) or x.ndim > 2:
            raise ValueError(f"expected an observation of shape ({self.obs_dim},) or (n, {self.obs_dim}), "
                             f"got {x.shape}")
        h = np.tanh(x @ self._w0_obs + self._b0_eff)
        for w, b in self._rest[:-1]:
            h = np.tanh(h @ w + b)
        w, b = self._rest[-1]
        out = h @ w + b
        gamma = self.action_low + self._scale / (1.0 + np.exp(-out))
        return np.clip(gamma, self.action_low, self.action_high).astype(np.float32, copy=False)

    def __repr__(self) -> str:
        return f"PASTAPolicy(path={str(self.path)!r}, preference={self.preference.tolist()})"


def load_policy(path: str | Path, preference: Any = None, obs_dim: int | None = None) -> PASTAPolicy:
    """Load a PASTA checkpoint as a fast deterministic gamma policy.

    Args:
        path: ``stem``, ``stem.json`` or ``stem.pt`` of a checkpoint written by
            :meth:`sofar_agents.PASTA.save`.
        preference: override of the deployment preference stored in the JSON.
        obs_dim: expected observation size; a checkpoint for another size raises
            ``ValueError``.

    Raises:
        FileNotFoundError: a checkpoint file is missing.
        ValueError: wrong format version, observation size or tensor shapes (the
            message names the file and the mismatch).
    """
    import torch  # imported lazily: only needed to read the tensor file

    meta, json_path, pt_path = read_checkpoint_metadata(path)
    if obs_dim is not None and meta["obs_dim"] != obs_dim:
        raise ValueError(f"{json_path}: checkpoint expects observations of size {meta['obs_dim']}, "
                         f"not {obs_dim}")
    try:
        state = torch.load(pt_path, map_location="cpu", weights_only=True)
    except Exception as err:  # noqa: BLE001 - re-raised with the file name
        raise ValueError(f"{pt_path}: cannot read the tensor file ({err})") from err
    if not isinstance(state, dict) or "actor" not in state:
        raise ValueError(f"{pt_path}: expected a dict with an 'actor' state dict")
    actor = {k: v.detach().cpu().numpy() for k, v in state["actor"].items()}
    layers = validate_actor_state(actor, meta, pt_path)
    return PASTAPolicy(layers, meta["obs_dim"], meta["preference"] if preference is None else preference,
                       meta["action_low"], meta["action_high"], path=json_path,
                       objective_names=meta.get("objective_names"))


def default_policy_path() -> Path:
    """Path of the PASTA policy shipped with the package (trained on Laguna Seca).

    Raises ``FileNotFoundError`` (with instructions) when it has not been trained yet.
    """
    from importlib.resources import files

    path = Path(str(files("sofar_agents") / "checkpoints" / "pasta_lagunaseca.json"))
    if not path.is_file():
        raise FileNotFoundError(
            f"no packaged PASTA policy at {path}. Train one with "
            "`python train/pasta.py --out runs/pasta` and copy runs/pasta/pasta_final.json and "
            "runs/pasta/pasta_final.pt to sofar_agents/checkpoints/ as pasta_lagunaseca.json and "
            "pasta_lagunaseca.pt (keep the 'weights_file' entry of the JSON in step), or use "
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
