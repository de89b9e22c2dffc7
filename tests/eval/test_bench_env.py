"""bench/bench_env.py: the throughput benchmark runs, repeats its timed passes and reports them."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]


def test_bench_env_reports_every_pass(tmp_path):
    out = tmp_path / "bench.json"
    subprocess.run([sys.executable, str(ROOT / "bench" / "bench_env.py"), "--steps", "15", "--repeats", "3",
                    "--json", str(out)], check=True, capture_output=True, text=True, timeout=300)
    result = json.loads(out.read_text())
    passes = result["steps_per_s_passes"]
    assert len(passes) == 3 and all(r > 0 for r in passes)
    assert result["steps_per_s_best"] == max(passes)
    assert min(passes) <= result["steps_per_s"] <= max(passes)
    # the host's state is recorded next to the rates: load average and a fixed reference workload
    ref = result["reference_workload_ms"]
    assert ref["before"] > 0 and ref["after"] > 0
    # the component breakdown accounts for the controller's two solvers
    assert result["breakdown_ms_per_step"]["mpc"] > 0 and result["breakdown_ms_per_step"]["miqp"] > 0
    # the compiled kernels inside them are timed too, and take part of their time
    kernels = result["compiled_ms_per_step"]
    assert kernels["compiled: MPC QP (PIQP or DAQP)"] > 0 and kernels["compiled: linearisation (generated C)"] > 0
    assert kernels["compiled: MPC QP (PIQP or DAQP)"] < result["breakdown_ms_per_step"]["mpc"]
    assert 0 <= kernels["compiled: DAQP (MIQP B&B)"] < result["breakdown_ms_per_step"]["miqp"]


def test_bench_env_runs_a_controller_preset(tmp_path):
    out = tmp_path / "bench.json"
    subprocess.run([sys.executable, str(ROOT / "bench" / "bench_env.py"), "--steps", "10", "--repeats", "1",
                    "--no-breakdown", "--stack", "sofar-recover", "--json", str(out)],
                   check=True, capture_output=True, text=True, timeout=300)
    result = json.loads(out.read_text())
    assert result["stack"] == "sofar-recover" and result["steps_per_s"] > 0


def test_bench_env_times_an_async_vector_env(tmp_path):
    out = tmp_path / "bench.json"
    subprocess.run([sys.executable, str(ROOT / "bench" / "bench_env.py"), "--steps", "10", "--repeats", "1",
                    "--vector", "2", "--json", str(out)], check=True, capture_output=True, text=True, timeout=300)
    vec = json.loads(out.read_text())["vector"]
    assert vec["workers"] == 2 and vec["vector_steps"] == 10
    assert vec["env_steps"] == 20  # no episode ends in 10 steps: every worker step counts
    assert vec["steps_per_s"] > 0


def test_bench_env_rejects_zero_repeats():
    proc = subprocess.run([sys.executable, str(ROOT / "bench" / "bench_env.py"), "--repeats", "0"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode != 0 and "--repeats" in proc.stderr


def test_compare_runs_interleaved_passes_of_both_revisions(tmp_path):
    """An A/A run against the checked-out commit: both sides run, and the ratio is reported from them."""
    if subprocess.run(["git", "-C", str(ROOT), "rev-parse", "HEAD"], capture_output=True).returncode != 0:
        pytest.skip("not a git checkout")
    out = tmp_path / "ab.json"
    subprocess.run([sys.executable, str(ROOT / "bench" / "bench_env.py"), "--compare", "HEAD", "--rounds", "1",
                    "--steps", "5", "--no-breakdown", "--json", str(out)],
                   check=True, capture_output=True, text=True, timeout=300)
    res = json.loads(out.read_text())
    old, new = res["old"]["steps_per_s"], res["new"]["steps_per_s"]
    assert len(old["values"]) == len(new["values"]) == 1 and old["median"] > 0 and new["median"] > 0
    assert res["ratio_of_medians"] == pytest.approx(new["median"] / old["median"])
    old_cpu, new_cpu = res["old"]["cpu_ms_per_step"]["median"], res["new"]["cpu_ms_per_step"]["median"]
    assert old_cpu > 0 and new_cpu > 0
    assert res["ratio"]["cpu_ms_per_step"]["of_medians"] == pytest.approx(new_cpu / old_cpu)
    assert res["old"]["commit"] == subprocess.run(["git", "-C", str(ROOT), "rev-parse", "HEAD"], capture_output=True,
                                                  text=True).stdout.strip()


def test_bench_train_rejects_zero_rounds():
    proc = subprocess.run([sys.executable, str(ROOT / "bench" / "bench_train.py"), "--compare", "HEAD", "--rounds", "0"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode != 0 and "--rounds" in proc.stderr


@pytest.mark.parametrize("argv", [
    ["--backends", "local"],                            # one backend: nothing to compare
    ["--backends", "local", "spark"],                   # not a backend of train/pasta.py
    ["--backends", "local", "local"],                   # the same twice
    ["--backends", "local", "processes", "--compare", "HEAD"],  # two modes at once
    [],                                                 # no mode
    ["--backends", "local", "processes", "--multi-agent", "1"],  # a race of one car
    ["--backends", "local", "processes", "--backend", "local"],  # --backend is for --compare
    ["--compare", "HEAD", "--scenario", "interactive"],  # the short default command has its own world
    ["--compare", "HEAD", "--backend", "spark"],        # not a set-up
])
def test_bench_train_rejects_bad_backend_lists(argv):
    proc = subprocess.run([sys.executable, str(ROOT / "bench" / "bench_train.py"), *argv],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and ("--backends" in proc.stderr or "--compare" in proc.stderr)


def test_bench_train_reads_the_collection_time_from_the_tensorboard_log(tmp_path):
    from torch.utils.tensorboard import SummaryWriter

    sys.path.insert(0, str(ROOT / "bench"))
    try:
        from bench_train import collect_time
    finally:
        sys.path.remove(str(ROOT / "bench"))
    writer = SummaryWriter(str(tmp_path / "tb" / "run"))
    for step, seconds in enumerate((1.5, 2.25, 0.75)):
        writer.add_scalar("time/collect_s", seconds, step)
        writer.add_scalar("time/update_s", 10.0, step)  # not collection
    writer.close()
    assert collect_time(tmp_path) == pytest.approx(4.5)
    with pytest.raises(RuntimeError, match="no TensorBoard log"):
        collect_time(tmp_path / "empty")


def test_bench_vector_reports_the_synthetic_ceiling(tmp_path):
    out = tmp_path / "vector.json"
    subprocess.run([sys.executable, str(ROOT / "bench" / "bench_vector.py"), "--no-sofar", "--steps", "20",
                    "--rounds", "2", "--work-ms", "0.5", "--json", str(out)],
                   check=True, capture_output=True, text=True, timeout=300)
    result = json.loads(out.read_text())
    assert "sofar_async_vector" not in result
    one = result["synthetic_one_process"]
    assert one["ratio_to_one_process"] == 1.0 and len(one["per_round"]) == 2
    names = ["synthetic_async_vector", "synthetic_bare_pipes", "synthetic_independent"]
    if result["pinned_cpus"] is not None:
        names.append("synthetic_async_vector_pinned")
    for name in names:
        row = result[name]
        assert row["steps_per_s"] > 0 and len(row["ratio_per_round"]) == 2
        # each ratio is its round's vector figure over the same round's one-process figure
        assert row["ratio_per_round"][0] == pytest.approx(row["per_round"][0] / one["per_round"][0])
    for rnd in result["synthetic_lockstep"]["per_round"]:
        # the parts of a vector step add up to it, and a worker's step costs at least its burnt CPU time
        parts = rnd["dispatch_ms"] + rnd["last_worker_step_ms"] + rnd["return_ms"]
        assert parts == pytest.approx(rnd["vector_step_ms"])
        assert rnd["slowest_worker_step_ms"] >= rnd["last_worker_step_ms"] >= 0.5
        assert rnd["slowest_worker_step_ms"] >= rnd["worker_step_ms"] >= 0.5
        assert rnd["dispatch_ms"] > 0 and rnd["return_ms"] > 0
        assert 0.5 <= rnd["worker_cpu_ms"] <= rnd["worker_step_ms"] + 0.05  # the burnt CPU time, within the wall time


def test_split_lockstep_on_known_stamps():
    sys.path.insert(0, str(ROOT / "bench"))
    try:
        from bench_vector import split_lockstep
    finally:
        sys.path.remove(str(ROOT / "bench"))
    # two vector steps [s]: the main process calls at 0 and 10, each worker starts 1 later, works 3 or 5
    calls = np.array([[0.0, 8.0], [10.0, 17.0]])
    stamps = [np.array([[1.0, 4.0], [11.0, 14.0]]), np.array([[1.0, 6.0], [12.0, 15.0]])]
    parts = split_lockstep(calls, stamps)
    # the second worker ends last in both steps: it starts 1 and 2 after the call, works 5 and 3
    assert parts["vector_step_ms"] == pytest.approx(7.5e3)
    assert parts["dispatch_ms"] == pytest.approx(1.5e3)
    assert parts["last_worker_step_ms"] == pytest.approx(4e3)
    assert parts["return_ms"] == pytest.approx(2e3)  # (8 - 6 + 17 - 15) / 2
    assert parts["worker_step_ms"] == pytest.approx(3.5e3)
    assert parts["slowest_worker_step_ms"] == pytest.approx(4e3)  # (5 + 3) / 2
    assert "worker_cpu_ms" not in parts  # no CPU times given
    with_cpu = split_lockstep(calls, [np.column_stack([s, [2.0, 3.0]]) for s in stamps])
    assert with_cpu["worker_cpu_ms"] == pytest.approx(2.5e3)
    assert {k: v for k, v in with_cpu.items() if k != "worker_cpu_ms"} == parts


def test_synthetic_env_burns_the_cpu_time_it_is_given():
    sys.path.insert(0, str(ROOT / "bench"))
    try:
        from bench_vector import SyntheticEnv
    finally:
        sys.path.remove(str(ROOT / "bench"))
    env = SyntheticEnv(work_ms=20.0, info_keys=5)
    obs, _ = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    import time

    t0 = time.thread_time()
    _, _, terminated, truncated, info = env.step(env.action_space.sample())
    assert time.thread_time() - t0 >= 0.020
    assert len(info) == 5 and not terminated and not truncated


@pytest.mark.parametrize("bad", [["--workers", "0"], ["--steps", "0"], ["--rounds", "0"], ["--work-ms", "0"],
                                 ["--info-keys", "-1"]])
def test_bench_vector_rejects_bad_options(bad):
    proc = subprocess.run([sys.executable, str(ROOT / "bench" / "bench_vector.py"), "--no-sofar", *bad],
                          check=False, capture_output=True, text=True, timeout=120)
    assert proc.returncode != 0 and bad[0] in proc.stderr
