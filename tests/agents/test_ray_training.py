"""PASTA training on Ray (``train/pasta.py --backend ray``): a short run writes a checkpoint that loads,
a seeded run equals the local backend's bit for bit, a dead worker leaves the agent unchanged, and
without Ray the script says how to install it."""

from __future__ import annotations

import json
import sys

import numpy as np
import pytest
import torch
from pool_runs import assert_identical, assert_rollouts_equal_local, env_fns, run_argv, small_agent, tensors
from test_train_smoke import _pasta_script as _script

from sofar_agents import PASTA, load_policy

ray = pytest.importorskip("ray")
from sofar_agents.pasta.ray_rollout import RayEnvPool


@pytest.fixture(scope="module")
def local_ray():
    ray.init(num_cpus=2, include_dashboard=False, logging_level="WARNING")
    yield
    ray.shutdown()


def test_ray_run_writes_a_checkpoint_that_loads_and_equals_the_local_run(tmp_path, local_ray):
    script = _script()
    on_ray = script.main(run_argv(tmp_path / "ray", "--backend", "ray", "--num-workers", "2"))
    local = script.main(run_argv(tmp_path / "local", "--backend", "local", "--n-envs", "2"))

    agent = PASTA.load(on_ray)
    assert agent.num_timesteps == 256 and agent.num_updates == 2
    meta = json.loads(on_ray.read_text())
    assert (meta["training"]["backend"], meta["training"]["num_workers"], meta["training"]["n_envs"]) == ("ray", 2, 2)
    gamma = load_policy(on_ray, obs_dim=12)(np.zeros(12, np.float32))
    assert gamma.shape == (1,) and 0.05 <= gamma[0] <= 1.0

    assert_identical(tensors(on_ray), tensors(local))  # weights and optimiser moments, bit for bit
    states = [json.loads(path.read_text())["state"] for path in (on_ray, local)]
    for state in states:
        state.pop("train_time_s")  # wall time
    assert states[0] == states[1]


def test_uneven_slices_and_chunk_size_do_not_change_the_rollouts(local_ray):
    pool = RayEnvPool(env_fns(3), num_workers=2, chunk_steps=5)  # envs {0, 1} and {2}; 5-step chunks
    assert_rollouts_equal_local(pool, 3)


def test_a_dead_worker_fails_the_rollout_and_leaves_the_agent_unchanged(local_ray):
    pool = RayEnvPool(env_fns(2), num_workers=2)
    agent = small_agent()
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
        script.main(run_argv(tmp_path / "run", "--backend", "ray", "--num-workers", "2"))
    assert exc.value.code == 2
    assert 'pip install "sofar[ray]"' in capsys.readouterr().err
    assert not (tmp_path / "run").exists()


def test_bad_ray_options_are_refused(capsys):
    script = _script()
    for argv, message in ((["--backend", "local", "--num-workers", "2"], "--num-workers needs --backend processes or ray"),
                          (["--backend", "ray", "--num-workers", "3", "--n-envs", "2"], "exceeds --n-envs"),
                          (["--backend", "spark"], "--backend must be")):
        with pytest.raises(SystemExit) as exc:
            script.parse_args(argv)
        assert exc.value.code == 2 and message in capsys.readouterr().err
