"""PASTA training in worker processes (``train/pasta.py --backend processes``): the rollouts and a seeded run's
checkpoint equal the local vector env's bit for bit, a dead or broken worker fails with an error naming it and
leaves the agent unchanged, and bad arguments are refused before any process starts."""

from __future__ import annotations

import functools
import json

import pytest
import torch
from pool_runs import assert_identical, assert_rollouts_equal_local, env_fns, run_argv, small_agent, tensors
from test_train_smoke import _pasta_script as _script

from sofar_agents.pasta.process_rollout import ProcessEnvPool
from sofar_agents.pasta.self_play import RaceVectorEnv, make_self_play_race


def test_rollouts_equal_the_local_vector_env_with_uneven_slices_and_short_chunks():
    pool = ProcessEnvPool(env_fns(3), num_workers=2, chunk_steps=5)  # envs {0, 1} and {2}; 5-step chunks
    assert pool.slices == [(0, 2), (2, 3)] and pool.num_envs == 3
    assert_rollouts_equal_local(pool, 3)  # closes the pool
    assert not any(proc.is_alive() for proc in pool._procs)
    with pytest.raises(RuntimeError, match="closed"):
        small_agent().collect(pool)
    pool.close()  # a second close does nothing


def test_self_play_races_in_worker_processes_equal_the_local_race_vector_env():
    races = [functools.partial(make_self_play_race, "LagunaSeca", 2, {"race": {"duration": 3.0}}) for _ in range(3)]
    pool = ProcessEnvPool(races, num_workers=2, chunk_steps=5, cars_per_race=2)  # races {0, 1} and {2}
    assert pool.slices == [(0, 4), (4, 6)] and pool.seed_offsets == [0, 2] and pool.num_envs == 6
    assert_rollouts_equal_local(pool, 6, local=RaceVectorEnv(races))


def test_processes_run_writes_the_checkpoint_of_the_local_run(tmp_path):
    script = _script()
    pooled = script.main(run_argv(tmp_path / "processes", "--backend", "processes", "--num-workers", "2"))
    local = script.main(run_argv(tmp_path / "local", "--backend", "local", "--n-envs", "2"))
    meta = json.loads(pooled.read_text())["training"]
    assert (meta["backend"], meta["num_workers"], meta["n_envs"]) == ("processes", 2, 2)
    assert_identical(tensors(pooled), tensors(local))  # weights and optimiser moments, bit for bit
    states = [json.loads(path.read_text())["state"] for path in (pooled, local)]
    for state in states:
        state.pop("train_time_s")  # wall time
    assert states[0] == states[1]


def test_a_failing_call_names_the_worker_and_leaves_the_pool_usable():
    pool = ProcessEnvPool(env_fns(2), num_workers=2, pin_workers=False)
    try:
        with pytest.raises(RuntimeError, match=r"rollout worker process 0 \(envs 0\.\.0\) failed: AttributeError"):
            pool.get_attr("no_such_attribute")
        assert pool.get_attr("objective_names")[1][0] == "safety"  # both answers of the failed call were read
    finally:
        pool.close()


def test_a_dead_worker_fails_the_rollout_and_leaves_the_agent_unchanged():
    pool = ProcessEnvPool(env_fns(2), num_workers=2, pin_workers=False)
    agent = small_agent()
    rng_state, torch_state = agent.rng.bit_generator.state, agent.torch_gen.get_state()
    try:
        pool._procs[1].kill()
        pool._procs[1].join()
        with pytest.raises(RuntimeError, match=r"rollout worker process 1 \(envs 1\.\.1\) failed"):
            agent.collect(pool)
        assert agent.num_timesteps == 0 and len(agent.ep_info_buffer) == 0
        assert agent.rng.bit_generator.state == rng_state and torch.equal(agent.torch_gen.get_state(), torch_state)
        assert pool.closed and not any(proc.is_alive() for proc in pool._procs)  # the failed rollout closed it
    finally:
        pool.close()


def test_a_worker_that_cannot_build_its_envs_fails_the_construction_with_its_error():
    message = r"rollout worker process 0 \(envs 0\.\.1\) failed: gymnasium\.error\.NameNotFound: .*NoSuchCircuit"
    with pytest.raises(RuntimeError, match=message):
        ProcessEnvPool(env_fns(2, "SOfAR-NoSuchCircuit-v0"), num_workers=1, pin_workers=False)


@pytest.mark.parametrize(("n_envs", "kwargs", "message"), [
    (2, {"num_workers": 0}, "num_workers must lie in"),
    (2, {"num_workers": 3}, "num_workers must lie in"),
    (2, {"num_workers": 2, "chunk_steps": 0}, "chunk_steps must be positive"),
    (2, {"num_workers": 2, "cars_per_race": 0}, "cars_per_race must be positive"),
])
def test_bad_arguments_are_refused_before_any_worker_starts(n_envs, kwargs, message, monkeypatch):
    started = []
    monkeypatch.setattr("multiprocessing.context.SpawnProcess.start", lambda self: started.append(self))
    with pytest.raises(ValueError, match=message):
        ProcessEnvPool(env_fns(n_envs), **kwargs)
    assert started == []


def test_bad_backend_options_are_refused(capsys):
    script = _script()
    for argv, message in ((["--backend", "local", "--num-workers", "2"], "--num-workers needs --backend processes or ray"),
                          (["--backend", "processes", "--address", "auto"], "--address needs --backend ray"),
                          (["--backend", "processes", "--num-workers", "3", "--n-envs", "2"], "exceeds --n-envs"),
                          (["--backend", "threads"], "--backend must be one of local, processes, ray")):
        with pytest.raises(SystemExit) as exc:
            script.parse_args(argv)
        assert exc.value.code == 2 and message in capsys.readouterr().err
    args, _ = script.parse_args(["--backend", "processes"])
    assert (args.n_envs, args.num_workers) == (1, 1)


@pytest.mark.parametrize(("argv", "backend", "n_envs", "num_workers"), [
    ([], "local", 1, None),                                   # one env: stepped in the learner's process
    (["--n-envs", "2"], "processes", 2, 2),                   # several: worker processes
    (["--num-workers", "2"], "processes", 2, 2),
    (["--n-envs", "4", "--num-workers", "2"], "processes", 4, 2),
    (["--n-envs", "4", "--num-workers", "3"], "processes", 4, 3),
    (["--n-envs", "2", "--multi-agent"], "processes", 2, 2),  # self-play: races in worker processes
    (["--multi-agent"], "local", 1, None),                    # one race: in the learner's process
    (["--n-envs", "2", "--backend", "local"], "local", 2, None),
])
def test_the_default_backend_is_worker_processes_for_several_envs(argv, backend, n_envs, num_workers, monkeypatch):
    script = _script()
    monkeypatch.setattr(script, "available_cpus", lambda: 2)
    args, _ = script.parse_args(argv)
    assert (args.backend, args.n_envs, args.num_workers) == (backend, n_envs, num_workers)


@pytest.mark.parametrize(("argv", "num_workers"), [
    (["--n-envs", "8"], 2),                                   # worker processes: at most one per CPU
    (["--n-envs", "8", "--backend", "ray"], 8),               # Ray: one per env (a cluster has its own CPUs)
    (["--n-envs", "8", "--num-workers", "4"], 4),             # asked for
])
def test_worker_processes_default_to_one_per_cpu(argv, num_workers, monkeypatch):
    script = _script()
    monkeypatch.setattr(script, "available_cpus", lambda: 2)
    assert script.parse_args(argv)[0].num_workers == num_workers
