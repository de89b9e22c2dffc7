"""Smoke tests of the training scripts, run as ``python train/<script>.py`` from the repo root.

They train on ``SOfAR-LagunaSeca-v0`` when ``sofar_env`` registers it, otherwise on the
cheap stand-in ``synthetic_envs:SOfARTest/SyntheticRace-v0`` (same interface), which the
scripts import through the ``module:id`` form of the id. ``SOFAR_SMOKE_ENV_ID`` overrides
the choice.
"""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np

from sofar_agents import PASTA, load_policy

ROOT = Path(__file__).resolve().parents[2]
HERE = Path(__file__).resolve().parent
REAL_ENV_ID = "SOfAR-LagunaSeca-v0"


def _env_id() -> str:
    forced = os.environ.get("SOFAR_SMOKE_ENV_ID")  # e.g. to check the scripts on the stand-in
    if forced:
        return forced
    try:
        import sofar_env  # noqa: F401  (registers the SOfAR ids when available)
    except ImportError:
        pass
    if REAL_ENV_ID not in gym.registry:
        try:
            from sofar_env.registration import register_envs

            register_envs()
        except ImportError:
            pass
    return REAL_ENV_ID if REAL_ENV_ID in gym.registry else "synthetic_envs:SOfARTest/SyntheticRace-v0"


def _run(script: str, *args: str, returncode: int = 0) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(HERE), env.get("PYTHONPATH")) if p)
    proc = subprocess.run([sys.executable, f"train/{script}", *args], cwd=ROOT, env=env, capture_output=True,
                          text=True, timeout=600)
    assert proc.returncode == returncode, f"stdout:\n{proc.stdout}\nstderr:\n{proc.stderr}"
    return proc


def _pasta_script():
    spec = importlib.util.spec_from_file_location("train_pasta_smoke", ROOT / "train" / "pasta.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses resolve their annotations through sys.modules
    spec.loader.exec_module(module)
    return module


def test_pasta_script_trains_logs_checkpoints_and_resumes(tmp_path: Path) -> None:
    env_id = _env_id()
    out = tmp_path / "run"
    common = ["--env-id", env_id, "--n-steps", "128", "--n-envs", "1", "--seed", "3", "--out", str(out),
              "--no-progress", "--n-epochs", "2"]
    if env_id == REAL_ENV_ID:
        common += ["--env-kwargs", '{"race": {"duration": 5.0}}']  # 50-step episodes: some finish
    first = _run("pasta.py", "--total-steps", "256", "--save-every", "1", *common)
    # one console line per update, returns labelled with the objective names
    assert "update 2  steps 256/256  episodes +" in first.stderr
    if env_id == REAL_ENV_ID:
        assert "mean returns of the last" in first.stderr and "overtakes " in first.stderr

    events = list((out / "tb").glob("events.out.tfevents.*"))
    assert events and all(e.stat().st_size > 0 for e in events)
    final = out / "pasta_final.json"
    assert final.is_file() and (out / "pasta_final.pt").is_file()
    assert sorted(p.name for p in (out / "checkpoints").glob("*.json")) == [
        "pasta_0000000128.json", "pasta_0000000256.json"]
    meta = json.loads(final.read_text())
    assert meta["format_version"] == 1 and meta["obs_dim"] == 12 and meta["n_objectives"] == 5
    assert meta["training"]["env_id"] == env_id and meta["training"]["seed"] == 3
    assert "train/pasta.py" in meta["training"]["command"]
    assert meta["state"]["num_timesteps"] == 256

    policy = load_policy(final, obs_dim=12)
    gamma = policy(np.zeros(12, np.float32))
    assert gamma.shape == (1,) and 0.05 <= gamma[0] <= 1.0

    before = final.read_bytes()
    refused = _run("pasta.py", "--total-steps", "384", *common, returncode=1)  # a new run into the folder
    assert "already holds a run" in refused.stderr and f"--resume {final}" in refused.stderr
    assert "--force" in refused.stderr and "overwrite" not in refused.stderr
    assert final.read_bytes() == before  # nothing overwritten

    # resuming a run in its own folder needs no --force
    _run("pasta.py", "--total-steps", "384", "--resume", str(final), "--save-every", "0", *common)
    resumed = PASTA.load(final)
    assert resumed.num_timesteps == 384 and resumed.num_updates == 3
    assert json.loads(final.read_text())["training"]["resumed_from"] == str(final)


def test_quick_preset_and_mu_decay_help() -> None:
    script = _pasta_script()
    args, overrides = script.parse_args(["--quick"])
    assert (args.total_steps, args.out, args.save_every) == (16384, "runs/pasta_quick", 8)
    assert overrides == {"n_steps": 512, "n_epochs": 4}
    assert script.env_kwargs_of(args)["race"] == {"duration": script.QUICK_EPISODE_S}
    args, overrides = script.parse_args(["--quick", "--total-steps", "1000", "--n-steps", "100",
                                         "--env-kwargs", '{"race": {"duration": 12.0}}'])
    assert args.total_steps == 1000 and overrides["n_steps"] == 100  # explicit options win
    assert script.env_kwargs_of(args)["race"] == {"duration": 12.0}
    args, overrides = script.parse_args([])
    assert not args.quick and overrides == {} and args.n_envs == 1 and "race" not in script.env_kwargs_of(args)
    args, _ = script.parse_args(["--resume", "runs/old/checkpoints/pasta_0000000128.json"])
    assert Path(args.out) == Path("runs/old").resolve()  # a resumed run continues in its own folder

    help_text = subprocess.run([sys.executable, "train/pasta.py", "--help"], cwd=ROOT, capture_output=True,
                               text=True, timeout=120, check=True, env={**os.environ, "COLUMNS": "2000"}).stdout
    entries = ["--" + " ".join(e.split()) for e in help_text.split("\n  --")[1:]]  # one per option, unwrapped
    lines = {e.split()[0].rstrip(","): e for e in entries}
    mu_help = lines["--mu-decay-steps"]
    assert "(default: --total-steps of a new run" in mu_help and "environment steps" in mu_help
    assert "1000000" not in mu_help
    assert "16384 steps" in lines["--quick"] and "already holds a run" in lines["--force"]


def test_ppo_script_trains_saves_and_resumes(tmp_path: Path) -> None:
    from stable_baselines3 import PPO

    from sofar_agents.policies import SB3Policy

    out = tmp_path / "ppo"
    common = ["--env-id", _env_id(), "--n-steps", "64", "--batch-size", "32", "--n-epochs", "1", "--out", str(out)]
    first = _run("ppo.py", "--total-steps", "128", "--save-every", "0", *common)
    assert "PPO: 100%" in first.stderr and "128/128" in first.stderr  # the progress bar
    assert list((out / "tb").rglob("events.out.tfevents.*"))
    final = out / "ppo_final.zip"
    policy = SB3Policy(final)
    gamma = policy(np.zeros(12, np.float32))
    assert gamma.shape == (1,) and 0.05 <= gamma[0] <= 1.0
    first_params = PPO.load(final, device="cpu").policy.state_dict()

    refused = _run("ppo.py", "--total-steps", "256", *common, returncode=1)  # a new run into the folder
    assert "already holds a run" in refused.stderr and "--resume" in refused.stderr
    _run("ppo.py", "--total-steps", "256", "--resume", str(final), "--no-progress", "--save-every", "64",
         *common)  # its own folder: no --force
    resumed = PPO.load(final, device="cpu")
    assert resumed.num_timesteps == 256
    assert sorted(p.name for p in (out / "checkpoints").glob("*.zip")) == ["ppo_192_steps.zip", "ppo_256_steps.zip"]
    assert any(not np.array_equal(first_params[k].numpy(), v.numpy())
               for k, v in resumed.policy.state_dict().items())  # it trained on
    assert (out / "ppo_final_vecnormalize.pkl").is_file()


def test_pasta_script_trains_in_the_interactive_world(tmp_path: Path) -> None:
    """``--scenario interactive``: a checkpoint of the 16-value observation that loads and drives the world."""
    import sofar_env  # noqa: F401

    out = tmp_path / "int"
    _run("pasta.py", "--scenario", "interactive", "--total-steps", "128", "--n-steps", "64", "--n-envs", "1",
         "--seed", "5", "--out", str(out), "--no-progress", "--n-epochs", "1",
         "--env-kwargs", '{"race": {"duration": 3.0}}')
    final = out / "pasta_final.json"
    meta = json.loads(final.read_text())
    assert meta["obs_dim"] == 16
    policy = load_policy(final, obs_dim=16)
    env = gym.make("SOfAR-LagunaSeca-Interactive-v0", race={"duration": 3.0})
    obs, _ = env.reset(seed=0)
    done = False
    while not done:
        gamma = policy(obs)
        assert env.action_space.contains(gamma)
        obs, _, terminated, truncated, info = env.step(gamma)
        done = terminated or truncated
    assert info["sim_time"] > 0.0


def test_circuits_give_each_env_its_circuit_and_bad_lists_are_usage_errors(tmp_path: Path) -> None:
    """``--circuits``: env i runs circuit i modulo their number, recorded in the checkpoint; a repeated circuit,
    an env count that is not a multiple of them, an unknown name or self-play is refused before anything runs."""
    import sofar_env  # noqa: F401

    script = _pasta_script()
    args, _ = script.parse_args(["--circuits", "Monza", "Kentucky", "--n-envs", "4", "--backend", "local",
                                 "--env-kwargs", '{"race": {"duration": 1.0}}'])
    vec = script.make_vec_env(args)
    try:
        vec.reset(seed=0)
        tracks = [t.name for t in vec.get_attr("track")]  # the circuit an env races on, known after its reset
    finally:
        vec.close()
    assert tracks == ["Monza", "Kentucky", "Monza", "Kentucky"]
    for bad, match in ([["--circuits", "Monza", "Monza", "--n-envs", "2"], "twice"],
                       [["--circuits", "Monza", "Kentucky", "--n-envs", "3"], "not a multiple"],
                       [["--circuits", "Spa"], "invalid choice"],
                       [["--circuits", "Monza", "--multi-agent"], "single-car"]):
        proc = _run("pasta.py", *bad, "--out", str(tmp_path / "never"), returncode=2)
        assert match in proc.stderr, proc.stderr
    assert not (tmp_path / "never").exists()
    out = tmp_path / "two"
    _run("pasta.py", "--scenario", "dynamic", "--circuits", "LagunaSeca", "Monza", "--n-envs", "2", "--backend",
         "local", "--total-steps", "64", "--n-steps", "32", "--seed", "5", "--out", str(out), "--no-progress",
         "--n-epochs", "1", "--env-kwargs", '{"race": {"duration": 2.0}}')
    assert json.loads((out / "pasta_final.json").read_text())["training"]["circuits"] == ["LagunaSeca", "Monza"]
