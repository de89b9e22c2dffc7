"""Worker processes end with their driver: a sweep of eval/table.py or a training run of train/pasta.py killed with
SIGKILL leaves no worker behind (the executor's process pool, the multi-agent pool and Ray actors; the training
pool's worker processes and Ray actors), and the pieces (sofar_agents.worker_lifetime)."""

from __future__ import annotations

import importlib.util
import multiprocessing as mp
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from sofar_agents.worker_lifetime import exit_with_parent, exit_with_process, process_alive, process_start_time

from .process_tree import alive, descendants, kill_all, wait_for

ROOT = Path(__file__).resolve().parents[2]
TABLE = ROOT / "eval" / "table.py"
TRAIN = ROOT / "train" / "pasta.py"
EXIT_S = 15.0
"""How long the workers may take to end after their driver was killed [s] (a worker killed while still importing
ends once its imports are done)."""
SMALL = ["--tracks", "LagunaSeca", "Monza", "--gammas", "0.5", "--no-adaptive", "--episodes", "2", "--duration", "200",
         "--no-progress"]


def _spawned(cmd: str) -> bool:
    return "spawn_main" in cmd


def _ray_actor(cmd: str) -> bool:
    return cmd.startswith("ray::_RunnerActor")


def _ray_rollout_actor(cmd: str) -> bool:
    return cmd.startswith("ray::_RaySlice")


def _not_ray_agent(cmd: str) -> bool:  # Ray's agents follow its raylet on Ray's own schedule (up to a minute)
    return not (cmd.startswith("ray::") and "Agent" in cmd)


TRAIN_LONG = ["--total-steps", "1000000", "--n-steps", "4096", "--save-every", "0", "--no-progress"]
"""A training run that is still collecting its first rollout when its driver is killed."""

CASES = {  # name: (script and its options, which descendants are the workers, which must end, seconds to start)
    "process-pool": ([TABLE, *SMALL, "--rhos", "0.5", "--workers", "2"], _spawned, lambda cmd: True, 120),
    "multi-agent-pool": ([TABLE, *SMALL, "--multi-agent", "--workers", "2"], _spawned, lambda cmd: True, 120),
    "ray-actors": ([TABLE, *SMALL, "--rhos", "0.5", "--backend", "ray", "--workers", "2"], _ray_actor, _not_ray_agent,
                   240),
    "training-processes": ([TRAIN, *TRAIN_LONG, "--backend", "processes", "--num-workers", "2", "--n-envs", "2"],
                           _spawned, lambda cmd: True, 120),
    "training-ray-actors": ([TRAIN, *TRAIN_LONG, "--backend", "ray", "--num-workers", "2", "--n-envs", "2"],
                            _ray_rollout_actor, _not_ray_agent, 240),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_killed_sweep_leaves_no_worker_behind(case, tmp_path):
    command, is_worker, must_end, start_s = CASES[case]
    if "ray" in case and importlib.util.find_spec("ray") is None:
        pytest.skip("Ray is not installed")
    driver = subprocess.Popen([sys.executable, *map(str, command), "--out", str(tmp_path / "out")], cwd=ROOT,
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True)
    tracked: dict = {}
    try:
        def workers_up() -> bool:
            tracked.update(descendants(driver.pid))
            return sum(is_worker(cmd) for cmd in descendants(driver.pid).values()) >= 2 or driver.poll() is not None

        assert wait_for(workers_up, start_s), f"no workers after {start_s} s"
        assert driver.poll() is None, driver.stderr.read().decode()[-3000:]
        time.sleep(3.0)  # let them get into their episodes or rollouts (still running when the driver dies)
        tracked.update(descendants(driver.pid))
        driver.send_signal(signal.SIGKILL)
        driver.wait(10)
        ours = [p for p, cmd in tracked.items() if must_end(cmd)]
        assert any(is_worker(cmd) for cmd in tracked.values())
        assert wait_for(lambda: not any(alive(p) for p in ours), EXIT_S), (
            "still running after the driver was killed: "
            + "; ".join(f"{p[0]} {tracked[p][:80]}" for p in ours if alive(p)))
    finally:
        if driver.poll() is None:
            driver.kill()
            driver.wait(10)
        kill_all(tracked)


def _child_of_child(ready, parent_pid) -> None:
    """A worker whose parent (the middle process) is killed: it must end."""
    exit_with_parent(parent_pid)
    ready.set()
    time.sleep(60)


def _middle(ready, pid_out) -> None:
    proc = mp.get_context("spawn").Process(target=_child_of_child, args=(ready, os.getpid()), daemon=False)
    proc.start()
    pid_out.value = proc.pid
    time.sleep(60)


def test_exit_with_parent_ends_a_worker_whose_parent_was_killed():
    ctx = mp.get_context("spawn")
    ready, pid_out = ctx.Event(), ctx.Value("i", 0)
    middle = ctx.Process(target=_middle, args=(ready, pid_out))
    middle.start()
    try:
        assert ready.wait(60)
        worker = next(p for p in descendants(middle.pid) if p[0] == pid_out.value)
        assert alive(worker)
        os.kill(middle.pid, signal.SIGKILL)
        middle.join(10)
        assert wait_for(lambda: not alive(worker), 5.0)
    finally:
        if middle.is_alive():
            middle.kill()


def test_process_alive_tells_a_process_from_its_end_and_its_pid_reused():
    me = os.getpid()
    assert process_alive(me) and process_alive(me, process_start_time(me))
    done = subprocess.Popen([sys.executable, "-c", "pass"])
    done.wait()
    assert not process_alive(done.pid)
    if process_start_time(me) is not None:  # Linux: another start time is another process
        assert not process_alive(me, "0")
    zombie = subprocess.Popen([sys.executable, "-c", "pass"])
    assert wait_for(lambda: not process_alive(zombie.pid), 10.0)  # ended but not yet reaped: not alive
    zombie.wait()


def test_exit_with_process_ends_when_the_followed_process_is_gone():
    code = ("import sys, time; from sofar_agents.worker_lifetime import exit_with_process; "
            "exit_with_process(int(sys.argv[1]), sys.argv[2] or None, poll_s=0.1); time.sleep(60)")
    followed = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        watcher = subprocess.Popen([sys.executable, "-c", code, str(followed.pid),
                                    process_start_time(followed.pid) or ""])
        time.sleep(1.0)
        assert watcher.poll() is None
        followed.kill()
        followed.wait()
        assert watcher.wait(10) == 1
    finally:
        followed.kill()
