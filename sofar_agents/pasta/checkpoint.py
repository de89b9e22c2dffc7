"""The PASTA checkpoint format: writing and reading it, for training and for deployment.

A checkpoint is a pair of files with a common stem (format_version 1):

- ``<stem>.json``: ``format_version``, ``algorithm``, ``weights_file``, ``weights_sha256`` (the SHA-256 of
  the tensor file), ``obs_dim``, ``n_objectives``, ``objective_names``, ``act_dim``, ``action_low``,
  ``action_high`` (within the gamma range [0.05, 1]), ``action_squashing`` (``"sigmoid"``:
  ``a = low + (high - low) * sigmoid(u)``, or ``"clip"``: ``a = clip(u, low, high)``; the same as
  ``config.action_squashing``), ``activation`` (``"tanh"``), the deployment ``preference``, the agent's
  ``seed``, the PASTA ``config``, the ``state`` counters and the agent's numpy generator state, the
  ``rollout`` state to resume from (:mod:`sofar_agents.pasta.resume`; absent when the agent has not
  collected yet) and ``training`` metadata (command, seed, env, code version, steps, wall time; for an
  agent trained by ``train/pasta.py``, the training environment's ``env_config_hash`` and resolved
  ``env_config``: :mod:`sofar_agents.pasta.env_record`; a checkpoint written before that record may have a
  sidecar ``<stem>.training_env.json``, recovered by seeded replays under its training commit, whose fields
  loading adds to the metadata: :mod:`sofar_agents.pasta.env_reconstruction`). Every
  field and its check: :mod:`sofar_agents.pasta.checkpoint_meta`.
- ``<stem>.pt``: ``torch.save`` of a dict of tensors and state dicts only (``actor``,
  ``critic``, ``optimizer``, the return normaliser statistics, the utopia, the agent's torch
  generator state ``torch_generator`` and the ``rollout`` tensors), read with
  ``torch.load(weights_only=True)``; never pickled Python objects.

Writing is atomic: both files are written to temporary files in their folder, then moved over the
old ones with ``os.replace``, the tensor file first and the JSON last, so that a save interrupted at
any point leaves the old pair, or a new tensor file with the old JSON, which reading refuses (its
``weights_sha256`` does not match), never a torn file. A save validates the JSON it is about to write
as reading would, and writes nothing if it fails.

Reading checks everything before anything is built: a file that is not a checkpoint
(random bytes, JSON of another kind, a truncated or foreign tensor file, missing keys or
tensors), every JSON field (type and range, :func:`~sofar_agents.pasta.checkpoint_meta.validate_metadata`),
NaN/inf in any tensor, the rollout state's shapes, and a tensor file that is not the one the JSON was
written with (``weights_sha256``; checkpoints written before the field are read without the check),
all raise ``ValueError`` naming the file and the field.

:func:`save_agent` / :func:`load_agent` back :meth:`PASTA.save` / :meth:`PASTA.load`;
:func:`read_checkpoint_metadata` and :func:`read_actor_layers` back the numpy policy
of :func:`sofar_agents.policies.load_policy`. torch is imported only inside the
functions that touch the tensor file, so that reading the metadata (and importing
:mod:`sofar_agents.policies`) does not import it.
"""

from __future__ import annotations

import copy
import hashlib
import io
import json
import os
import re
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from sofar_agents.file_modes import publish_mode
from sofar_agents.pasta.checkpoint_meta import FORMAT_VERSION, validate_metadata
from sofar_agents.pasta.config import PASTAConfig
from sofar_agents.pasta.env_reconstruction import sidecar_record
from sofar_agents.pasta.env_record import training_env_record
from sofar_agents.pasta.resume import RolloutState, check_rollout_meta

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

def checkpoint_paths(path: str | Path) -> tuple[Path, Path]:
    """``(json_path, pt_path)`` for a checkpoint path given as ``stem``, ``stem.json`` or ``stem.pt``."""
    p = Path(path)
    stem = p.with_suffix("") if p.suffix in (".json", ".pt") else p
    return Path(f"{stem}.json"), Path(f"{stem}.pt")


def read_checkpoint_metadata(path: str | Path) -> tuple[dict[str, Any], Path, Path]:
    """Read and validate the JSON half of a checkpoint.

    Returns ``(metadata, json_path, pt_path)``. Raises ``FileNotFoundError`` when a
    file is missing and ``ValueError`` (naming the file and the field) for a wrong format
    version or any field of the wrong type, out of range or inconsistent with the others.
    """
    json_path, pt_path = checkpoint_paths(path)
    if not json_path.is_file():
        raise FileNotFoundError(f"checkpoint metadata {json_path} not found")
    try:
        meta = json.loads(json_path.read_bytes())
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise ValueError(f"{json_path}: not a valid JSON checkpoint ({err})") from err
    validate_metadata(meta, json_path)
    if meta.get("rollout") is not None:
        check_rollout_meta(meta["rollout"], str(json_path))
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


def read_tensors(pt_path: Path) -> dict[str, Any]:
    """The tensor dict of a checkpoint (``torch.load(weights_only=True)`` on the CPU).

    Raises ``ValueError`` (naming the file) when it cannot be read, has no ``actor`` or holds NaN/inf.
    """
    return _load_tensors(pt_path)[0]


def _load_tensors(pt_path: Path) -> tuple[dict[str, Any], str]:
    """:func:`read_tensors` and the SHA-256 of the bytes it read."""
    import torch

    try:
        data = Path(pt_path).read_bytes()
        state = torch.load(io.BytesIO(data), map_location="cpu", weights_only=True)
    except Exception as err:  # noqa: BLE001 - re-raised with the file name
        raise ValueError(f"{pt_path}: cannot read the tensor file ({err})") from err
    if not isinstance(state, dict) or not isinstance(state.get("actor"), dict):
        raise ValueError(f"{pt_path}: expected a dict with an 'actor' state dict")
    for name, tensor in _tensors(state):
        if tensor.is_floating_point() and not bool(torch.isfinite(tensor).all()):
            raise ValueError(f"{pt_path}: tensor {name} is not finite (NaN or inf)")
    return state, hashlib.sha256(data).hexdigest()


def _check_digest(meta: dict[str, Any], digest: str, json_path: Path, pt_path: Path) -> None:
    """``ValueError`` naming both files unless the tensor file is the one the JSON was written with."""
    expected = meta.get("weights_sha256")
    if expected is not None and expected != digest:
        raise ValueError(f"{json_path} and {pt_path} are not one checkpoint: weights_sha256 {expected} in the "
                         f"JSON, {digest} for the tensor file (a save interrupted between its two files, or "
                         "files of two saves); use a complete pair")


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


def read_actor_layers(meta: dict[str, Any], pt_path: Path,
                      json_path: Path | None = None) -> list[tuple[np.ndarray, np.ndarray]]:
    """The actor's ``(weight, bias)`` pairs as numpy arrays, checked against ``meta`` (and, when it has
    ``weights_sha256``, that ``pt_path`` is the tensor file it was written with; ``json_path`` names it)."""
    state, digest = _load_tensors(pt_path)
    layers = validate_actor_state(_actor_arrays(state), meta, pt_path)
    _check_digest(meta, digest, json_path or Path("the checkpoint JSON"), pt_path)
    return layers


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (np.floating, np.integer, np.bool_)):
        return obj.item()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"{type(obj).__name__} is not JSON serialisable")


def save_agent(agent: PASTA, path: str | Path, metadata: dict[str, Any] | None = None) -> Path:
    """Write ``agent`` as ``<stem>.pt`` (tensors only) and ``<stem>.json`` (everything else), atomically.

    ``path`` may end in ``.json``, ``.pt`` or have no such suffix. ``metadata``
    (e.g. the training command and env id) is merged into ``agent.metadata`` and
    stored under ``"training"``. Besides the weights, the optimiser and the counters, the
    checkpoint holds the agent's generator states and its collector's rollout state, so that
    training resumed from it continues exactly (:mod:`sofar_agents.pasta.resume`). Both files are
    written to temporary files in their folder and moved into place with ``os.replace``, the JSON
    last (module docstring); a JSON that reading would refuse raises ``ValueError`` before anything
    is written. Returns the JSON path.
    """
    import torch

    json_path, pt_path = checkpoint_paths(path)
    if metadata:
        agent.metadata.update(metadata)
    state = {
        "actor": agent.actor.state_dict(),
        "critic": agent.critic.state_dict(),
        "optimizer": agent.optimizer.state_dict(),
        "return_rms_mean": torch.as_tensor(agent.return_rms.mean),
        "return_rms_var": torch.as_tensor(agent.return_rms.var),
        "return_rms_count": torch.tensor(agent.return_rms.count, dtype=torch.float64),
        "torch_generator": agent.torch_gen.get_state(),
    }
    if agent.utopia is not None:
        state["utopia"] = torch.as_tensor(agent.utopia)
    rollout: RolloutState | None = agent._rollout.checkpoint_state()
    rollout_meta = None
    if rollout is not None:
        rollout_meta, state["rollout"] = rollout.to_checkpoint()
    buf = io.BytesIO()
    torch.save(state, buf)
    data = buf.getvalue()
    try:
        from importlib.metadata import version

        code_version = version("sofar")
    except Exception:  # noqa: BLE001 - not installed as a distribution
        code_version = "unknown"
    meta = {
        "format_version": FORMAT_VERSION,
        "algorithm": "PASTA",
        "weights_file": pt_path.name,
        "weights_sha256": hashlib.sha256(data).hexdigest(),
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
            "rng": agent.rng.bit_generator.state,
        },
        "training": {
            **agent.metadata,
            **training_env_record(agent.metadata),  # env_config_hash, env_config (pasta.env_record)
            "code_version": code_version,
            "torch_version": torch.__version__,
            "saved_at": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        },
    }
    if rollout_meta is not None:
        meta["rollout"] = rollout_meta
    text = json.dumps(meta, indent=2, default=_json_default)
    check = json.loads(text)
    validate_metadata(check, json_path)  # never write a checkpoint that reading would refuse
    if rollout_meta is not None:
        check_rollout_meta(check["rollout"], str(json_path))
    _write_pair(pt_path, data, json_path, text.encode())
    return json_path


def _write_pair(pt_path: Path, pt_data: bytes, json_path: Path, json_data: bytes) -> None:
    """Write both files to temporary files in their folders, then ``os.replace`` them, the JSON last.

    A failure (or an interrupt) at any point removes the temporary files still there and leaves the
    old files, or the new tensor file with the old JSON (which reading refuses by its digest).
    """
    tmp: list[Path] = []
    try:
        for target, data in ((pt_path, pt_data), (json_path, json_data)):
            target.parent.mkdir(parents=True, exist_ok=True)
            fd, name = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=".tmp")
            tmp.append(Path(name))
            with os.fdopen(fd, "wb") as f:
                publish_mode(f.fileno(), target)
                f.write(data)
                f.flush()
                os.fsync(f.fileno())
        for src, target in zip(list(tmp), (pt_path, json_path)):
            os.replace(src, target)
            tmp.remove(src)
        _sync_folder(json_path.parent)
    finally:
        for leftover in tmp:
            leftover.unlink(missing_ok=True)


def _sync_folder(folder: Path) -> None:
    """fsync a folder, so that the renames in it survive a crash (where the platform allows it)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


_AGENT_TENSORS = ("actor", "critic", "return_rms_mean", "return_rms_var", "return_rms_count")
"""Entries of the tensor file that :func:`load_agent` needs (``optimizer`` and ``utopia`` are optional)."""


def load_agent(cls: type[PASTA], path: str | Path) -> PASTA:
    """Rebuild an agent of class ``cls`` from a checkpoint written by :func:`save_agent`.

    Raises ``FileNotFoundError`` for a missing file and ``ValueError`` (naming the
    file and the field) for a wrong format version, a JSON field of the wrong type or
    out of range, a tensor file that cannot be read, holds NaN/inf or lacks an entry,
    weights that do not match the metadata, a rollout state of the wrong shapes and a
    tensor file that is not the one the JSON was written with. Every part is read and
    checked before the agent is returned, so a failed load hands back nothing half-built.
    The agent's generators and its collector's rollout state are restored when the
    checkpoint has them (older checkpoints: the generators start from the seed and the
    first rollout begins with a seeded reset).
    """
    import torch

    meta, json_path, pt_path = read_checkpoint_metadata(path)
    try:
        config = PASTAConfig.from_dict(meta["config"])
    except (TypeError, ValueError, KeyError) as err:
        raise ValueError(f"{json_path}: invalid config ({err})") from err
    state, digest = _load_tensors(pt_path)
    missing = [key for key in _AGENT_TENSORS if key not in state]
    if missing:
        raise ValueError(f"{pt_path}: tensor file is missing {missing}")
    validate_actor_state(_actor_arrays(state), meta, pt_path)
    _check_digest(meta, digest, json_path, pt_path)
    torch_state = state.get("torch_generator")
    if torch_state is not None:
        try:
            torch.Generator().set_state(torch_state)
        except (RuntimeError, TypeError) as err:
            raise ValueError(f"{pt_path}: tensor torch_generator is not a torch generator state ({err})") from err
    rollout = None
    if meta.get("rollout") is not None:
        rollout = RolloutState.from_checkpoint(meta["rollout"], state.get("rollout"), str(pt_path),
                                               (meta["obs_dim"], meta["n_objectives"]))
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
    if "rng" in meta.get("state", {}):
        agent.rng.bit_generator.state = meta["state"]["rng"]
    if torch_state is not None:
        agent.torch_gen.set_state(torch_state)
    if rollout is not None:
        agent._rollout.restore(rollout)
    agent.metadata = copy.deepcopy(meta.get("training", {}))
    if "env_config_hash" not in agent.metadata:  # written before the record: its sidecar, if replayed since
        agent.metadata.update(sidecar_record(Path(json_path)))
    return agent
