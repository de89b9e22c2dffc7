"""PASTA training on Ray (``train/pasta.py --backend ray``): a short run writes a checkpoint that loads,
a seeded run equals the local backend's bit for bit, a dead worker leaves the agent unchanged, and
without Ray the script says how to install it."""

from __future__ import annotations

import functools
import json
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch

from sofar_agents import PASTA, PASTAConfig, load_policy
from sofar_agents.pasta.rollout import make_training_env
from test_train_smoke import _pasta_script as _script

ray = pytest.importorskip("ray")
from sofar_agents.pasta.ray_rollout import RayEnvPool  # noqa: E402

ENV_ID = "SOfAR-LagunaSeca-v0"
SHORT = {"race": {"duration": 3.0}}  # 30-step episodes: several end (and are bootstrapped) per rollout


@pytest.fixture(scope="module")
def local_ray():
    ray.init(num_cpus=2, include_dashboard=False, logging_level="WARNING")
    yield
    ray.shutdown()


def _argv(out: Path, *extra: str) -> list[str]:
    return ["--env-id", ENV_ID, "--env-kwargs", json.dumps(SHORT), "--seed", "4", "--total-steps", "256",
            "--n-steps", "64", "--n-epochs", "2", "--hidden-sizes", "32", "32", "--save-every", "0",
            "--no-progress", "--out", str(out), *extra]


def _tensors(json_path: Path) -> dict:
    return torch.load(json_path.with_suffix(".pt"), weights_only=True)


def _assert_identical(a, b, where: str = "") -> None:
    """Nested dicts / lists of tensors and numbers, equal bit for bit."""
    assert type(a) is type(b), where
    if isinstance(a, dict):
        assert a.keys() == b.keys(), where
        for key in a:
            _assert_identical(a[key], b[key], f"{where}.{key}")
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b)):
            _assert_identical(x, y, f"{where}[{i}]")
    elif isinstance(a, torch.Tensor):
        assert torch.equal(a, b), where
    else:
        assert a == b, where


def test_ray_run_writes_a_checkpoint_that_loads_and_equals_the_local_run(tmp_path, local_ray):
    script = _script()
    on_ray = script.main(_argv(tmp_path / "ray", "--backend", "ray", "--num-workers", "2"))
    local = script.main(_argv(tmp_path / "local", "--n-envs", "2"))

    agent = PASTA.load(on_ray)
    assert agent.num_timesteps == 256 and agent.num_updates == 2
    meta = json.loads(on_ray.read_text())
    assert (meta["training"]["backend"], meta["training"]["num_workers"], meta["training"]["n_envs"]) == ("ray", 2, 2)
    gamma = load_policy(on_ray, obs_dim=12)(np.zeros(12, np.float32))
    assert gamma.shape == (1,) and 0.05 <= gamma[0] <= 1.0

    _assert_identical(_tensors(on_ray), _tensors(local))  # weights and optimiser moments, bit for bit
    states = [json.loads(path.read_text())["state"] for path in (on_ray, local)]
    for state in states:
        state.pop("train_time_s")  # wall time
    assert states[0] == states[1]


def _fns(n: int) -> list:
    return [functools.partial(make_training_env, ENV_ID, SHORT, 0.1, 0.8) for _ in range(n)]


def _agent() -> PASTA:
    config = PASTAConfig(n_steps=48, n_epochs=1, hidden_sizes=(16, 16), critic_head_hidden=8)
    return PASTA(12, 5, [0.05], [1.0], config, seed=9)


def test_uneven_slices_and_chunk_size_do_not_change_the_rollouts(local_ray):
    venv = gym.vector.SyncVectorEnv(_fns(3), autoreset_mode=gym.vector.AutoresetMode.SAME_STEP)
    pool = RayEnvPool(_fns(3), num_workers=2, chunk_steps=5)  # envs {0, 1} and {2}; 5-step chunks
    try:
        local, remote = _agent(), _agent()
        for _ in range(2):
            a, b = local.collect(venv), remote.collect(pool)
            for field in ("obs", "preferences", "pre_actions", "actions", "log_probs", "rewards", "values",
                          "next_values", "terminated", "truncated"):
                assert np.array_equal(getattr(a, field), getattr(b, field)), field
            assert a.truncated.any()  # episodes ended inside the rollout (preference draws, bootstrapping)
            assert [e["length"] for e in a.episodes] == [e["length"] for e in b.episodes]
            local.update(a)
            remote.update(b)
        assert np.array_equal(local.return_rms.var, remote.return_rms.var)
        assert pool.get_attr("objective_names") == venv.get_attr("objective_names")
    finally:
        pool.close()
        venv.close()


def test_a_dead_worker_fails_the_rollout_and_leaves_the_agent_unchanged(local_ray):
    pool = RayEnvPool(_fns(2), num_workers=2)
    agent = _agent()
    rng_state, torch_state = agent.rng.bit_generator.state, agent.torch_gen.get_state()
    try:
        ray.kill(pool.actors[1], no_restart=True)
        with pytest.raises(RuntimeError, match="Ray rollout worker 1"):
            agent.collect(pool)
        assert agent.num_timesteps == 0 and len(agent.ep_info_buffer) == 0
        assert agent.rng.bit_generator.state == rng_state and torch.equal(agent.torch_gen.get_state(), torch_state)
    finally:
        pool.close()


def test_ray_backend_without_ray_says_how_to_install(tmp_path, monkeypatch, capsys):
    script = _script()
    monkeypatch.setitem(sys.modules, "ray", None)  # "import ray" now raises ImportError
    with pytest.raises(SystemExit) as exc:
        script.main(_argv(tmp_path / "run", "--backend", "ray", "--num-workers", "2"))
    assert exc.value.code == 2
    assert 'pip install "sofar[ray]"' in capsys.readouterr().err
    assert not (tmp_path / "run").exists()


def test_bad_ray_options_are_refused(capsys):
    script = _script()
    for argv, message in ((["--num-workers", "2"], "need --backend ray"),
                          (["--backend", "ray", "--num-workers", "3", "--n-envs", "2"], "exceeds --n-envs"),
                          (["--backend", "spark"], "--backend must be")):
        with pytest.raises(SystemExit) as exc:
            script.parse_args(argv)
        assert exc.value.code == 2 and message in capsys.readouterr().err
