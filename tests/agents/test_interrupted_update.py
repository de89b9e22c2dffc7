"""An interrupt (Ctrl-C) inside a rollout or an update leaves the agent as it was before that rollout: what is saved
then equals the checkpoint of the last finished update, and training continued in the same process gives what an
uninterrupted run gives."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import gymnasium as gym
import pytest
import torch

from pool_runs import assert_identical
from sofar_agents import PASTA, PASTAConfig
from sofar_agents.pasta import agent as agent_module
from sofar_agents.pasta.rollout import make_training_env

N_ENVS, N_STEPS = 2, 32
CONFIG = PASTAConfig(n_steps=N_STEPS, n_epochs=2, batch_size=16, hidden_sizes=(16, 16), critic_head_hidden=8)
"""64 transitions per update: 4 minibatches per epoch, 8 optimiser steps per update."""


def _vec_env() -> gym.vector.SyncVectorEnv:
    fns = [lambda: make_training_env("SOfARTest/SyntheticRace-v0", {"max_steps": 23}, 0.1, 0.8)] * N_ENVS
    return gym.vector.SyncVectorEnv(fns, autoreset_mode=gym.vector.AutoresetMode.SAME_STEP)


def _agent() -> PASTA:
    return PASTA(12, 5, [0.05], [1.0], CONFIG, seed=5)


def _nth_call_raises(mp: pytest.MonkeyPatch, obj: object, name: str, n: int, after: bool) -> None:
    """Make ``obj.name``'s ``n``-th call raise KeyboardInterrupt, before or after doing its work."""
    real, calls = getattr(obj, name), {"n": 0}

    def fake(*args, **kwargs):
        calls["n"] += 1
        if calls["n"] == n and not after:
            raise KeyboardInterrupt
        out = real(*args, **kwargs)
        if calls["n"] == n:
            raise KeyboardInterrupt
        return out
    mp.setattr(obj, name, fake)


def _in_ppo_epochs(mp: pytest.MonkeyPatch, agent: PASTA, venv) -> None:
    def interrupted(*args, **kwargs):  # the utopia, the regrets and mu have moved by now
        raise KeyboardInterrupt
    mp.setattr(agent_module, "ppo_epochs", interrupted)


# (id, how the second update is interrupted)
INTERRUPTS: list[tuple[str, Callable]] = [
    ("first-env-step", lambda mp, a, v: _nth_call_raises(mp, v, "step", 1, after=False)),
    ("mid-rollout-env-step", lambda mp, a, v: _nth_call_raises(mp, v, "step", 20, after=True)),
    ("before-the-ppo-epochs", _in_ppo_epochs),
    ("after-the-first-optimiser-step", lambda mp, a, v: _nth_call_raises(mp, a.optimizer, "step", 1, after=True)),
    ("after-the-last-optimiser-step", lambda mp, a, v: _nth_call_raises(mp, a.optimizer, "step", 8, after=True)),
]


def _state(path: Path) -> tuple[dict, dict]:
    meta = json.loads(path.read_text())
    meta["state"].pop("train_time_s")
    return torch.load(path.with_suffix(".pt"), weights_only=True), {k: meta[k] for k in ("state", "rollout")}


@pytest.mark.parametrize(("name", "interrupt"), INTERRUPTS, ids=[i[0] for i in INTERRUPTS])
def test_an_interrupted_update_saves_the_state_before_it(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                         name: str, interrupt: Callable) -> None:
    """The second update is interrupted; the optimiser-step cases fail without the fix (weights and optimiser
    moved, counters not)."""
    torch.set_num_threads(1)
    uninterrupted, venv = _agent(), _vec_env()
    uninterrupted.learn(venv, 2 * N_STEPS * N_ENVS)
    expected = uninterrupted.save(tmp_path / "uninterrupted")
    venv.close()

    agent, venv = _agent(), _vec_env()
    agent.learn(venv, N_STEPS * N_ENVS)
    boundary = agent.save(tmp_path / "boundary")
    with monkeypatch.context() as mp:
        interrupt(mp, agent, venv)
        with pytest.raises(KeyboardInterrupt):
            agent.learn(venv, N_STEPS * N_ENVS)
    saved = agent.save(tmp_path / "after_interrupt")
    assert (agent.num_timesteps, agent.num_updates) == (N_STEPS * N_ENVS, 1)
    assert_identical(_state(saved), _state(boundary))  # the last consistent state, not a half-applied update

    agent.learn(venv, N_STEPS * N_ENVS)  # the envs are rebuilt from the saved rollout state
    venv.close()
    assert_identical(_state(agent.save(tmp_path / "continued")), _state(expected))
