"""What the tests of the actor-pool backends (``--backend processes`` and ``ray``) share: a short training run
that ends several episodes per rollout, its checkpoint's tensors, and a bit-for-bit comparison."""

from __future__ import annotations

import functools
import json
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch

from sofar_agents import PASTA, PASTAConfig
from sofar_agents.pasta.rollout import make_training_env

ENV_ID = "SOfAR-LagunaSeca-v0"
SHORT = {"race": {"duration": 3.0}}  # 30-step episodes: several end (and are bootstrapped) per rollout
BUFFER_FIELDS = ("obs", "preferences", "pre_actions", "actions", "log_probs", "rewards", "values", "next_values",
                 "terminated", "truncated")


def run_argv(out: Path, *extra: str) -> list[str]:
    """Options of a 256-step ``train/pasta.py`` run into ``out``."""
    return ["--env-id", ENV_ID, "--env-kwargs", json.dumps(SHORT), "--seed", "4", "--total-steps", "256",
            "--n-steps", "64", "--n-epochs", "2", "--hidden-sizes", "32", "32", "--save-every", "0",
            "--no-progress", "--out", str(out), *extra]


def env_fns(n: int, env_id: str = ENV_ID) -> list:
    """``n`` picklable training-env factories of ``env_id`` with short episodes."""
    return [functools.partial(make_training_env, env_id, SHORT, 0.1, 0.8) for _ in range(n)]


def small_agent() -> PASTA:
    config = PASTAConfig(n_steps=48, n_epochs=1, hidden_sizes=(16, 16), critic_head_hidden=8)
    return PASTA(12, 5, [0.05], [1.0], config, seed=9)


def tensors(json_path: Path) -> dict:
    return torch.load(json_path.with_suffix(".pt"), weights_only=True)


def assert_identical(a, b, where: str = "") -> None:
    """Nested dicts / lists of tensors and numbers, equal bit for bit."""
    assert type(a) is type(b), where
    if isinstance(a, dict):
        assert a.keys() == b.keys(), where
        for key in a:
            assert_identical(a[key], b[key], f"{where}.{key}")
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b)):
            assert_identical(x, y, f"{where}[{i}]")
    elif isinstance(a, torch.Tensor):
        assert torch.equal(a, b), where
    else:
        assert a == b, where


def assert_rollouts_equal_local(pool, n_envs: int, local=None) -> None:
    """Two rollouts and updates of a small agent through ``pool`` (an actor pool over ``env_fns(n_envs)``) equal,
    bit for bit, those through ``local`` (default: a ``SyncVectorEnv`` of the same envs); closes both.

    The learner runs one torch thread, as ``train/pasta.py`` does by default: the workers evaluate the policy
    with one, and a batch split over several threads may round differently in its last bits."""
    venv = local if local is not None else gym.vector.SyncVectorEnv(
        env_fns(n_envs), autoreset_mode=gym.vector.AutoresetMode.SAME_STEP)
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        assert pool.single_observation_space == venv.single_observation_space
        local, remote = small_agent(), small_agent()
        for _ in range(2):
            a, b = local.collect(venv), remote.collect(pool)
            for field in BUFFER_FIELDS:
                assert np.array_equal(getattr(a, field), getattr(b, field)), field
            assert a.truncated.any()  # episodes ended inside the rollout (preference draws, bootstrapping)
            assert [e["length"] for e in a.episodes] == [e["length"] for e in b.episodes]
            local.update(a)
            remote.update(b)
        assert np.array_equal(local.return_rms.var, remote.return_rms.var)
        assert pool.get_attr("objective_names") == tuple(venv.get_attr("objective_names"))
    finally:
        torch.set_num_threads(threads)
        pool.close()
        venv.close()
