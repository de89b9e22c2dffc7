"""The training environment of a checkpoint written before checkpoints recorded it, recovered by replay.

Checkpoints of ``train/pasta.py`` record their training environment's configuration hash
(:mod:`sofar_agents.pasta.env_record`). Older ones record the keyword arguments and the commit only, and a name
such as ``"sofar"`` meant another controller then than now. ``eval/training_env.py record`` replays seeded
episodes of such an environment under a checkout of the recorded commit and under the current code with the
name it has today (``stack="sofar-1"``); :func:`backfill_checkpoint` takes those pairs of recordings
(:class:`Replay`), one per training stage of a resumed run, and writes the checkpoint's **sidecar**,
``<stem>.training_env.json`` beside ``<stem>.json`` (:func:`sidecar_path`):

* ``policy_id``: the id result rows give the checkpoint (the SHA-1 of its two files,
  :func:`~sofar_agents.evaluation.files.content_id`): the sidecar belongs to exactly those files;
* ``env_config_reconstructed``: every stage replayed (the commit, the keyword arguments then and now, how much was
  compared, whether it was identical to the bit, the first difference otherwise, the hash of the configuration
  it names today, the two recordings), the stages no checkout can replay and why, and the command;
* ``env_config_hash`` and ``env_config``, as a new checkpoint records them in its ``training`` object, only when
  the last stage (the checkpoint's own environment: its ``env_id``, ``env_kwargs`` and ``multi_agent``) replayed
  identically.

The checkpoint's own files are left as they are: their SHA-1 is the policy id every table made with them carries.
:func:`sidecar_record` is what :meth:`PASTA.load <sofar_agents.pasta.agent.PASTA.load>` adds to the ``metadata``
of a checkpoint without its own record. Nothing is written when an argument is wrong (a replay of a commit the
checkpoint does not record, recordings of two different environments, a recording under other code than this
one); the sidecar is replaced atomically.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from sofar_agents.evaluation.files import content_id, write_json_atomic
from sofar_agents.pasta.env_record import training_env_record

__all__ = ["SIDECAR_SUFFIX", "Replay", "backfill_checkpoint", "recorded_commits", "sidecar_path", "sidecar_record"]

logger = logging.getLogger(__name__)

SIDECAR_SUFFIX = ".training_env.json"
"""The suffix of a checkpoint's sidecar: ``pasta_lagunaseca.json`` -> ``pasta_lagunaseca.training_env.json``."""

_FIELDS = ("env_config_hash", "env_config", "env_config_reconstructed")
_SAME = ("env_id", "multi_agent", "cars", "episodes", "steps")


def sidecar_path(checkpoint: Path) -> Path:
    """The sidecar of the checkpoint whose JSON is ``checkpoint``."""
    return checkpoint.with_name(checkpoint.stem + SIDECAR_SUFFIX)


def _files(checkpoint: Path) -> tuple[Path, Path]:
    meta = json.loads(checkpoint.read_text())
    return checkpoint, checkpoint.with_name(meta["weights_file"])


def sidecar_record(checkpoint: Path) -> dict[str, Any]:
    """The sidecar's ``env_config_hash``, ``env_config`` and ``env_config_reconstructed`` (those it has), or
    ``{}`` without a sidecar; a sidecar written for other files (its ``policy_id``) is ignored, with a warning."""
    path = sidecar_path(checkpoint)
    if not path.is_file():
        return {}
    side = json.loads(path.read_text())
    if side.get("policy_id") != content_id(*_files(checkpoint)):
        logger.warning("%s belongs to other files than %s (policy id %s): ignored", path, checkpoint,
                       side.get("policy_id"))
        return {}
    return {key: side[key] for key in _FIELDS if key in side}


@dataclass(frozen=True)
class Replay:
    """Two recordings of one training environment: under the training commit (``then``) and now (``now``).

    ``then`` and ``now`` are the recordings' metadata; ``decisions`` counts the recorded decisions of every car
    (a race of 4 cars over 300 steps: 1,200 per episode); ``first_difference`` is ``None`` when every array is
    identical to the bit.
    """

    then: dict[str, Any]
    now: dict[str, Any]
    arrays: int
    decisions: int
    first_difference: str | None
    paths: tuple[str, ...] = ()
    """The two recordings' files, as given (kept in the checkpoint's record)."""

    @classmethod
    def load(cls, then_path: Path, now_path: Path) -> Replay:
        then, now = np.load(then_path), np.load(now_path)
        meta_then, meta_now = json.loads(str(then["meta"])), json.loads(str(now["meta"]))
        for key in _SAME:
            if meta_then.get(key) != meta_now.get(key):
                raise ValueError(f"{then_path} and {now_path} record different {key}: {meta_then.get(key)!r} "
                                 f"and {meta_now.get(key)!r}")
        names = sorted(set(then.files) - {"meta"})
        if names != sorted(set(now.files) - {"meta"}):
            raise ValueError(f"{then_path} and {now_path} hold different arrays")
        first = None
        for name in names:
            x, y = then[name], now[name]
            if x.shape != y.shape:
                first = f"{name}: {x.shape[0]} against {y.shape[0]} rows"
            elif not np.array_equal(x, y, equal_nan=True):
                row = int(np.argwhere(~((x == y) | (np.isnan(x) & np.isnan(y))))[0][0])
                first = f"{name}: row {row} of {x.shape[0]}"
            if first:
                break
        return cls(meta_then, meta_now, len(names), sum(int(then[n].shape[0]) for n in names if n.endswith(
            ("|reward", "|race"))), first, (str(then_path), str(now_path)))

    @property
    def identical(self) -> bool:
        return self.first_difference is None

    def training_metadata(self) -> dict[str, Any]:
        """The run metadata (:func:`~sofar_agents.pasta.env_record.training_env_record`) of the ``now`` side."""
        return {"env_id": self.now["env_id"], "env_kwargs": self.now["env_kwargs"],
                "multi_agent": self.now["multi_agent"]}


def recorded_commits(training: dict[str, Any]) -> list[str]:
    """The commits a checkpoint's ``training`` object records, its own and those of its stages, as written."""
    found = [training.get("code_commit")] + [h.get("code_commit") for h in training.get("history") or ()]
    return [c for c in dict.fromkeys(found) if isinstance(c, str) and c]


def _matching(commit: str, recorded: Sequence[str]) -> str | None:
    full = commit.removesuffix("+dirty")
    for entry in recorded:
        short = entry.split()[0].removesuffix("+dirty")
        if len(short) >= 7 and full.startswith(short):
            return entry
    return None


def _stage(replay: Replay, recorded: Sequence[str], current_env: str) -> dict[str, Any]:
    as_recorded = _matching(replay.then["commit"], recorded)
    if as_recorded is None:
        raise ValueError(f"the replay of commit {replay.then['commit']} is of no commit the checkpoint records "
                         f"({', '.join(recorded) or 'none'})")
    if Path(replay.now["sofar_env"]).resolve() != Path(current_env).resolve():
        raise ValueError(f"the 'now' recording ran {replay.now['sofar_env']}, not this code ({current_env})")
    record = training_env_record(replay.training_metadata()) if replay.identical else {}
    return {"commit": replay.then["commit"], "recorded_as": as_recorded, "replayed_against": replay.now["commit"],
            "env_id": replay.now["env_id"], "multi_agent": replay.now["multi_agent"], "cars": replay.now["cars"],
            "env_kwargs_then": replay.then["env_kwargs"], "env_kwargs_now": replay.now["env_kwargs"],
            "episodes": replay.now["episodes"], "decisions": replay.decisions, "arrays": replay.arrays,
            "identical": replay.identical, "first_difference": replay.first_difference, "evidence": list(replay.paths),
            "env_config_hash": record.get("env_config_hash")}


def backfill_checkpoint(checkpoint: Path, replays: Sequence[Replay], unverified: Sequence[str],
                        command: str, note: str | None = None) -> dict[str, Any]:
    """Write the reconstruction (module docstring) into the sidecar of ``checkpoint``; return what it holds.

    ``replays`` are in the order of the training stages, the checkpoint's own environment last; ``note``, if
    given, is kept with them (e.g. where a replay that differs was traced to).
    """
    import sofar_env

    if not replays:
        raise ValueError("no replay given")
    training = dict(json.loads(checkpoint.read_text()).get("training") or {})
    if training.get("env_config_hash"):
        raise ValueError(f"{checkpoint} records its training environment already ({training['env_config_hash']})")
    recorded = recorded_commits(training)
    stages = [_stage(r, recorded, str(Path(sofar_env.__file__).parent)) for r in replays]
    last = replays[-1]
    own = (last.then["env_id"] == training.get("env_id") and last.then["env_kwargs"] == dict(
        training.get("env_kwargs") or {}) and bool(training.get("multi_agent")) == last.then["multi_agent"])
    if not own:
        raise ValueError("the last replay is not of the checkpoint's own environment (env_id, env_kwargs, "
                         "multi_agent of its training object)")
    side: dict[str, Any] = {"checkpoint": checkpoint.name, "policy_id": content_id(*_files(checkpoint))}
    if last.identical:
        side.update(training_env_record(last.training_metadata()))
    side["env_config_reconstructed"] = {
        "method": "seeded replay under the recorded commit and under the current code, compared to the bit "
                  "(observations, vector rewards, ends of episode; eval/training_env.py)",
        "stages": stages, "unverified": list(unverified), "command": command, **({"note": note} if note else {})}
    write_json_atomic(sidecar_path(checkpoint), side, indent=2)
    if not last.identical:
        logger.warning("%s: its own environment did not replay identically (%s): no env_config_hash written",
                       checkpoint, last.first_difference)
    return side
