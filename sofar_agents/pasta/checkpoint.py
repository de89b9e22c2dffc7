"""The PASTA checkpoint format: writing and reading it, for training and for deployment.

A checkpoint is a pair of files with a common stem (format_version 1):

- ``<stem>.json``: ``format_version``, ``algorithm``, ``weights_file``, ``obs_dim``,
  ``n_objectives``, ``objective_names``, ``act_dim``, ``action_low``, ``action_high``,
  ``action_squashing`` (``"sigmoid"``: ``a = low + (high - low) * sigmoid(u)``, or
  ``"clip"``: ``a = clip(u, low, high)``; the same as ``config.action_squashing``),
  ``activation`` (``"tanh"``), the deployment ``preference``, the agent's ``seed``,
  the PASTA ``config``, the optimiser ``state`` counters and ``training`` metadata
  (command, seed, env, code version, steps, wall time).
- ``<stem>.pt``: ``torch.save`` of a dict of tensors and state dicts only (``actor``,
  ``critic``, ``optimizer``, the return normaliser statistics, the utopia), read with
  ``torch.load(weights_only=True)``; never pickled Python objects.

Reading checks everything before anything is built: a file that is not a checkpoint
(random bytes, JSON of another kind, a truncated or foreign tensor file, missing keys or
tensors), NaN/inf in any tensor or in the preference and action bounds, action bounds
with ``action_low >= action_high``, and a preference of the wrong length, with a negative
entry or without a positive finite sum all raise ``ValueError`` naming the file and the
field.

:func:`save_agent` / :func:`load_agent` back :meth:`PASTA.save` / :meth:`PASTA.load`;
:func:`read_checkpoint_metadata` and :func:`read_actor_layers` back the numpy policy
of :func:`sofar_agents.policies.load_policy`. torch is imported only inside the
functions that touch the tensor file, so that reading the metadata (and importing
:mod:`sofar_agents.policies`) does not import it.
"""

from __future__ import annotations

import copy
import json
import re
import time
from pathlib import Path
from collections.abc import Iterator
from typing import TYPE_CHECKING, Any

import numpy as np

from sofar_agents.pasta.config import SQUASHINGS, PASTAConfig

if TYPE_CHECKING:
    from sofar_agents.pasta.agent import PASTA

__all__ = [
    "FORMAT_VERSION",
    "checkpoint_paths",
    "read_checkpoint_metadata",
    "read_tensors",
    "validate_actor_state",
    "read_actor_layers",
    "save_agent",
    "load_agent",
]

FORMAT_VERSION = 1
"""Version of the PASTA checkpoint format written and accepted by this package."""

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
        meta = json.loads(json_path.read_bytes())
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
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
    for key in ("obs_dim", "n_objectives"):
        if not isinstance(meta[key], int) or isinstance(meta[key], bool) or meta[key] < 1:
            raise ValueError(f"{json_path}: {key} must be a positive integer, got {meta[key]!r}")
    if not isinstance(meta["config"], dict):
        raise ValueError(f"{json_path}: config must be a JSON object, got {type(meta['config']).__name__}")
    k = meta["n_objectives"]
    preference = _finite_vector(meta, "preference", json_path)
    if len(preference) != k:
        raise ValueError(f"{json_path}: preference has {len(preference)} entries for {k} objectives")
    if np.any(preference < 0):
        raise ValueError(f"{json_path}: preference must be non-negative, got {meta['preference']}")
    if not (np.isfinite(preference.sum()) and preference.sum() > 0):
        raise ValueError(f"{json_path}: preference must sum to a positive finite value, got {meta['preference']}")
    if "objective_names" in meta and len(meta["objective_names"]) != k:
        raise ValueError(f"{json_path}: {len(meta['objective_names'])} objective names for {k} objectives")
    low = _finite_vector(meta, "action_low", json_path)
    high = _finite_vector(meta, "action_high", json_path)
    if len(low) != len(high) or len(low) == 0:
        raise ValueError(f"{json_path}: action_low and action_high differ in length or are empty")
    if np.any(low >= high):
        raise ValueError(f"{json_path}: action_low {meta['action_low']} must lie below action_high "
                         f"{meta['action_high']} in every component")
    squashing = meta.get("action_squashing", "sigmoid")
    if squashing not in SQUASHINGS or meta.get("activation", "tanh") != "tanh":
        raise ValueError(f"{json_path}: unsupported squashing/activation "
                         f"{meta.get('action_squashing')!r}/{meta.get('activation')!r}")
    config = meta["config"]
    if config.get("action_squashing", "sigmoid") != squashing:
        raise ValueError(f"{json_path}: action_squashing {squashing!r} disagrees with the config's "
                         f"{config.get('action_squashing', 'sigmoid')!r}")
    if "weights_file" in meta:
        pt_path = json_path.parent / meta["weights_file"]
    if not pt_path.is_file():
        raise FileNotFoundError(f"checkpoint weights {pt_path} (referenced by {json_path}) not found")
    return meta, json_path, pt_path


def _finite_vector(meta: dict[str, Any], key: str, json_path: Path) -> np.ndarray:
    """``meta[key]`` as a 1-D float array; ``ValueError`` naming the file and the field unless finite."""
    value = meta[key]
    if not isinstance(value, list) or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                              for v in value):
        raise ValueError(f"{json_path}: {key} must be a list of numbers, got {value!r}")
    arr = np.asarray(value, dtype=np.float64)
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{json_path}: {key} must be finite, got {value}")
    return arr


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


def read_tensors(pt_path: Path) -> dict[str, Any]:
    """The tensor dict of a checkpoint (``torch.load(weights_only=True)`` on the CPU).

    Raises ``ValueError`` (naming the file) when it cannot be read or has no ``actor``.
    """
    import torch

    try:
        state = torch.load(pt_path, map_location="cpu", weights_only=True)
    except Exception as err:  # noqa: BLE001 - re-raised with the file name
        raise ValueError(f"{pt_path}: cannot read the tensor file ({err})") from err
    if not isinstance(state, dict) or not isinstance(state.get("actor"), dict):
        raise ValueError(f"{pt_path}: expected a dict with an 'actor' state dict")
    for name, tensor in _tensors(state):
        if tensor.is_floating_point() and not bool(torch.isfinite(tensor).all()):
            raise ValueError(f"{pt_path}: tensor {name} is not finite (NaN or inf)")
    return state


def _tensors(obj: Any, prefix: str = "") -> Iterator[tuple[str, Any]]:
    """``(dotted name, tensor)`` for every tensor in the nested dicts/lists of a tensor file."""
    import torch

    if isinstance(obj, torch.Tensor):
        yield prefix, obj
    elif isinstance(obj, dict):
        for k, v in obj.items():
            yield from _tensors(v, f"{prefix}.{k}" if prefix else str(k))
    elif isinstance(obj, (list, tuple)):
        for i, v in enumerate(obj):
            yield from _tensors(v, f"{prefix}.{i}")


def _actor_arrays(state: dict[str, Any]) -> dict[str, np.ndarray]:
    return {k: v.detach().cpu().numpy() for k, v in state["actor"].items()}


def read_actor_layers(meta: dict[str, Any], pt_path: Path) -> list[tuple[np.ndarray, np.ndarray]]:
    """The actor's ``(weight, bias)`` pairs as numpy arrays, checked against ``meta``."""
    return validate_actor_state(_actor_arrays(read_tensors(pt_path)), meta, pt_path)


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (np.floating, np.integer, np.bool_)):
        return obj.item()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"{type(obj).__name__} is not JSON serialisable")


def save_agent(agent: PASTA, path: str | Path, metadata: dict[str, Any] | None = None) -> Path:
    """Write ``agent`` as ``<stem>.pt`` (tensors only) and ``<stem>.json`` (everything else).

    ``path`` may end in ``.json``, ``.pt`` or have no such suffix. ``metadata``
    (e.g. the training command and env id) is merged into ``agent.metadata`` and
    stored under ``"training"``. Returns the JSON path.
    """
    import torch

    json_path, pt_path = checkpoint_paths(path)
    json_path.parent.mkdir(parents=True, exist_ok=True)
    if metadata:
        agent.metadata.update(metadata)
    state = {
        "actor": agent.actor.state_dict(),
        "critic": agent.critic.state_dict(),
        "optimizer": agent.optimizer.state_dict(),
        "return_rms_mean": torch.as_tensor(agent.return_rms.mean),
        "return_rms_var": torch.as_tensor(agent.return_rms.var),
        "return_rms_count": torch.tensor(agent.return_rms.count, dtype=torch.float64),
    }
    if agent.utopia is not None:
        state["utopia"] = torch.as_tensor(agent.utopia)
    torch.save(state, pt_path)
    try:
        from importlib.metadata import version

        code_version = version("sofar")
    except Exception:  # noqa: BLE001 - not installed as a distribution
        code_version = "unknown"
    meta = {
        "format_version": FORMAT_VERSION,
        "algorithm": "PASTA",
        "weights_file": pt_path.name,
        "obs_dim": agent.obs_dim,
        "n_objectives": agent.n_objectives,
        "objective_names": list(agent.objective_names),
        "act_dim": agent.act_dim,
        "action_low": [float(str(v)) for v in agent.action_low],
        "action_high": [float(str(v)) for v in agent.action_high],
        "action_squashing": agent.config.action_squashing,
        "activation": "tanh",
        "preference": [float(v) for v in agent.preference],
        "seed": agent.seed,
        "config": agent.config.to_dict(),
        "state": {
            "num_timesteps": agent.num_timesteps,
            "num_updates": agent.num_updates,
            "mu": agent.mu_controller.mu,
            "last_conflict": agent.last_conflict,
            "train_time_s": agent.train_time,
        },
        "training": {
            **agent.metadata,
            "code_version": code_version,
            "torch_version": torch.__version__,
            "saved_at": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        },
    }
    json_path.write_text(json.dumps(meta, indent=2, default=_json_default))
    return json_path


_AGENT_TENSORS = ("actor", "critic", "return_rms_mean", "return_rms_var", "return_rms_count")
"""Entries of the tensor file that :func:`load_agent` needs (``optimizer`` and ``utopia`` are optional)."""


def load_agent(cls: type[PASTA], path: str | Path) -> PASTA:
    """Rebuild an agent of class ``cls`` from a checkpoint written by :func:`save_agent`.

    Raises ``FileNotFoundError`` for a missing file and ``ValueError`` (naming the
    file and the field) for a wrong format version, non-finite or inconsistent
    metadata, a tensor file that cannot be read, holds NaN/inf or lacks an entry,
    and weights that do not match the metadata. Every part is read and checked
    before the agent is returned, so a failed load hands back nothing half-built.
    """
    meta, json_path, pt_path = read_checkpoint_metadata(path)
    try:
        config = PASTAConfig.from_dict(meta["config"])
    except (TypeError, ValueError, KeyError) as err:
        raise ValueError(f"{json_path}: invalid config ({err})") from err
    state = read_tensors(pt_path)
    missing = [key for key in _AGENT_TENSORS if key not in state]
    if missing:
        raise ValueError(f"{pt_path}: tensor file is missing {missing}")
    validate_actor_state(_actor_arrays(state), meta, pt_path)
    try:
        agent = cls(
            meta["obs_dim"], meta["n_objectives"], meta["action_low"], meta["action_high"], config,
            preference=meta["preference"], seed=meta.get("seed", 0),
            objective_names=meta.get("objective_names"),
        )
        agent.actor.load_state_dict(state["actor"])
        agent.critic.load_state_dict(state["critic"])
        if "optimizer" in state:
            agent.optimizer.load_state_dict(state["optimizer"])
        rms_mean = state["return_rms_mean"].numpy().astype(np.float64)
        rms_var = state["return_rms_var"].numpy().astype(np.float64)
        rms_count = float(state["return_rms_count"])
        utopia = state["utopia"].numpy().astype(np.float64) if "utopia" in state else None
        st = meta.get("state", {})
        counters = (int(st.get("num_timesteps", 0)), int(st.get("num_updates", 0)),
                    float(st.get("mu", config.mu_max)), float(st.get("last_conflict", 0.0)),
                    float(st.get("train_time_s", 0.0)))
    except (RuntimeError, TypeError, ValueError, KeyError, AttributeError) as err:
        raise ValueError(f"{pt_path}: weights do not match the configuration in {json_path}: {err}") from err
    agent.return_rms.mean, agent.return_rms.var, agent.return_rms.count = rms_mean, rms_var, rms_count
    if utopia is not None:
        agent.utopia = utopia
    (agent.num_timesteps, agent.num_updates, agent.mu_controller.mu, agent.last_conflict,
     agent.train_time) = counters
    agent.metadata = copy.deepcopy(meta.get("training", {}))
    return agent
