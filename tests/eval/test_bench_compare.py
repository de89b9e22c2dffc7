"""bench/bench_env.py --compare and --compare-stack (bench/bench_compare.py, bench/bench_pass.py): the passes are made
through the public constructor only, time CPU and wall time, and the table reports their ratios."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _bench_module(name: str):
    sys.path.insert(0, str(ROOT / "bench"))
    try:
        return __import__(name)
    finally:
        sys.path.remove(str(ROOT / "bench"))


def test_compare_builds_passes_through_the_public_constructor(tmp_path):
    """A pass of --compare is gymnasium.make of the registered id with keys every revision accepts; the world
    and the controller are added only where they are not the defaults, the comparison's own options stay out."""
    bench_env, bench_compare = _bench_module("bench_env"), _bench_module("bench_compare")
    args = bench_env.build_parser().parse_args(["--compare", "2e40063", "--steps", "50", "--rounds=3",
                                                "--json", "x.json", "--repeats", "2"])
    env_id, kwargs = bench_compare.env_spec(args)
    assert env_id == "SOfAR-LagunaSeca-v0"
    assert kwargs == {"rho": 0.5, "n_opponents": 4, "timing_info": False}
    cmd = bench_compare.pass_command(env_id, kwargs, args, tmp_path / "p.json")
    assert cmd[1] == str(ROOT / "bench" / "bench_pass.py")
    options = dict(zip(cmd[2::2], cmd[3::2]))
    assert options == {"--env-id": env_id, "--kwargs": json.dumps(kwargs), "--steps": "50", "--gamma": "0.5",
                       "--seed": "0", "--json": str(tmp_path / "p.json")}
    args = bench_env.build_parser().parse_args(["--compare", "main", "--scenario", "interactive", "--stack", "paper",
                                                "--opponents", "2", "--rho", "0.7", "--track", "Monza",
                                                "--vector", "2"])
    env_id, kwargs = bench_compare.env_spec(args)
    assert env_id == "SOfAR-Monza-v0"
    assert kwargs == {"rho": 0.7, "n_opponents": 2, "timing_info": False, "scenario": "interactive",
                      "stack": "paper"}
    assert bench_compare.pass_command(env_id, kwargs, args, tmp_path / "p.json")[-2:] == ["--vector", "2"]
    # --compare-stack: the overrides replace the preset on the new side only
    overrides = {"mpc": {"qp_solver": "daqp"}}
    assert bench_compare.env_spec(bench_env.build_parser().parse_args([]), stack=overrides)[1]["stack"] == overrides


def _pass(cpu_ms: float, wall_ms: float) -> dict:
    return {"cpu_ms_per_step": cpu_ms, "wall_ms_per_step": wall_ms, "steps_per_s": 1e3 / wall_ms,
            "step_ms": {"median": wall_ms}, "episodes_ended": 0, "reference_workload_ms": {"after": 10.0},
            "load_average_1min": {"after": 1.0}}


def test_compare_table_reports_cpu_and_wall_time_ratios(capsys):
    bench_compare = _bench_module("bench_compare")
    old = [_pass(2.0, 3.0), _pass(2.2, 5.0), _pass(1.8, 2.5)]
    new = [_pass(1.0, 2.0), _pass(1.0, 2.5), _pass(1.2, 2.0)]
    side = bench_compare._side_summary(old)
    assert side["cpu_ms_per_step"]["median"] == pytest.approx(2.0)
    assert (side["cpu_ms_per_step"]["min"], side["cpu_ms_per_step"]["max"]) == pytest.approx((1.8, 2.2))
    assert side["wall_ms_per_step"]["median"] == pytest.approx(3.0)
    ratio = bench_compare.ratios(old, new)
    assert ratio["cpu_ms_per_step"]["of_medians"] == pytest.approx(1.0 / 2.0)
    # per round: each new pass over the old pass of its round
    assert ratio["cpu_ms_per_step"]["per_round"]["values"] == pytest.approx([0.5, 1.0 / 2.2, 1.2 / 1.8])
    assert ratio["cpu_ms_per_step"]["per_round"]["median"] == pytest.approx(0.5)
    assert ratio["wall_ms_per_step"]["of_medians"] == pytest.approx(2.0 / 3.0)
    assert ratio["steps_per_s"]["of_medians"] == pytest.approx(1.5)
    result = {"track": "LagunaSeca", "scenario": "paper", "stack": "sofar", "rho": 0.5, "opponents": 4,
              "gamma": 0.5, "steps": 10, "rounds": 3, "seed": 0, "cpu_count": 2, "ratio": ratio,
              "old": {"rev": "2e40063", "commit": "2e40063" + "0" * 33, **side},
              "new": {"rev": "working tree", "commit": "f" * 40, "dirty": True,
                      **bench_compare._side_summary(new)}}
    bench_compare._print(result)
    out = capsys.readouterr().out
    assert "old 2e40063 (2e4006300): 2.000 ms CPU per step median [1.800, 2.200], 3.000 ms wall" in out
    assert "new working tree (fffffffff, modified): 1.000 ms CPU per step median" in out
    assert "CPU time per step new/old: 0.500 of the medians; per round median 0.500 [0.455, 0.667]" in out
    assert "wall time per step new/old: 0.667 of the medians" in out


@pytest.mark.parametrize("argv", [
    ["--compare", "HEAD", "--compare-stack", "{}"],                   # two modes
    ["--compare-stack", "[1]"],                                        # not an object
    ["--compare-stack", "{mpc"],                                       # not JSON
    ["--compare-stack", '{"mpc": {"qp_solver": "daqp"}}', "--stack", "paper"],  # overrides of the default only
    ["--new-stack", "sofar-1"],                                       # an option of --compare
    ["--compare", "HEAD", "--new-stack", "no-such-preset"],           # not a preset
])
def test_compare_stack_rejects_bad_arguments(argv):
    proc = subprocess.run([sys.executable, str(ROOT / "bench" / "bench_env.py"), *argv],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "--compare" in proc.stderr


def test_compare_new_stack_changes_the_working_tree_side_only():
    bench_env = _bench_module("bench_env")
    args = bench_env.build_parser().parse_args(["--compare", "2e40063", "--new-stack", "sofar-1"])
    assert args.new_stack == "sofar-1" and args.stack == "sofar"
    # the revision's side keeps the keys every revision accepts (env_spec); the preset goes to the new side
    assert "stack" not in _bench_module("bench_compare").env_spec(args)[1]


def test_same_trajectories_needs_one_digest_on_both_sides():
    same = _bench_module("bench_compare").same_trajectories
    a, b = {"trajectory_digest": "a"}, {"trajectory_digest": "b"}
    assert same([a, a], [a]) is True
    assert same([a, a], [b]) is False
    assert same([a, b], [a]) is False   # a side that is not reproducible is not "identical" either
    assert same([a], [{}]) is None       # a pass of a script without digests


def test_a_pass_times_cpu_and_wall_time_of_the_package_it_imports(tmp_path):
    def run(name, gamma):
        out = tmp_path / name
        subprocess.run([sys.executable, str(ROOT / "bench" / "bench_pass.py"), "--kwargs",
                        '{"n_opponents": 1, "timing_info": false}', "--steps", "5", "--warm-up", "1",
                        "--gamma", gamma, "--json", str(out)],
                       check=True, capture_output=True, text=True, timeout=300, cwd=str(tmp_path))
        return json.loads(out.read_text())

    res = run("pass.json", "0.5")
    assert res["steps"] == 5 and res["env_id"] == "SOfAR-LagunaSeca-v0"
    assert res["cpu_ms_per_step"] > 0 and res["wall_ms_per_step"] > 0
    assert res["cpu_s"] == pytest.approx(5e-3 * res["cpu_ms_per_step"])
    assert Path(res["package"]) == ROOT / "sofar_env"
    # the digest of the trajectory: the same seeded pass gives the same one, another action another
    assert run("again.json", "0.5")["trajectory_digest"] == res["trajectory_digest"]
    assert run("other.json", "0.05")["trajectory_digest"] != res["trajectory_digest"]
