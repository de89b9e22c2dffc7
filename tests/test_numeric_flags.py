"""Numeric flags of the eval/, bench/ and train/ scripts: a value outside what the flag means (0 or a negative count, a
zero duration, a gamma outside the action range, nan) is a usage error, exit status 2, found while parsing, before
any work; 0 never stands for "not given". Each script's parser is caught as it parses (nothing runs)."""

from __future__ import annotations

import argparse
import importlib.util
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPTS = sorted(str(p.relative_to(ROOT)) for d in ("eval", "bench", "train") for p in (ROOT / d).glob("*.py")
                 if "parse_args(" in p.read_text())
_MODULES: dict[str, object] = {}


class _Parsed(Exception):
    """Raised instead of returning from ``parse_args``: the parse succeeded (the script stops there)."""

    def __init__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace) -> None:
        super().__init__("parsed")
        self.parser, self.namespace = parser, namespace


def _script(path: str):
    if path not in _MODULES:
        spec = importlib.util.spec_from_file_location(f"_flags_{Path(path).stem}_{Path(path).parent.name}", ROOT / path)
        module = importlib.util.module_from_spec(spec)
        sys.modules[spec.name] = module  # dataclasses in the script look their module up
        sys.path.insert(0, str((ROOT / path).parent))  # the eval and bench scripts import their siblings
        try:
            spec.loader.exec_module(module)
        finally:
            sys.path.remove(str((ROOT / path).parent))
        _MODULES[path] = module
    return _MODULES[path]


@pytest.fixture
def parse_only(monkeypatch):
    """``parse_args`` that raises :class:`_Parsed` after a successful parse (a usage error still exits 2)."""
    real = argparse.ArgumentParser.parse_args

    def parse(self, args=None, namespace=None):
        raise _Parsed(self, real(self, args, namespace))

    monkeypatch.setattr(argparse.ArgumentParser, "parse_args", parse)


def _run(path: str, argv: list[str]) -> _Parsed:
    with pytest.raises(_Parsed) as caught:
        _script(path).main(argv)
    return caught.value


@pytest.mark.parametrize("path", SCRIPTS)
def test_no_numeric_flag_takes_a_bare_int_or_float(path, parse_only):
    """Every number goes through an argument type of sofar_agents.cli_types (or its own check), never int/float."""
    argv = {"eval/plot_training.py": ["run"], "eval/headroom.py": ["x.csv"], "eval/paired.py": ["x.csv"],
            "eval/interventions.py": ["x.csv"], "eval/trajectories.py": ["record", "--out", "x.npz"],
            "bench/bench_train.py": ["--compare", "HEAD"], "eval/reference_numerics.py": ["sweep"],
            "eval/manifest.py": ["list"], "eval/pasta_preference.py": ["probe"],
            "eval/stall_probe.py": ["x.csv", "--out", "x"],
            "eval/off_tracks.py": ["--replay", "x.csv", "--out", "x"], "eval/safety_signals.py": ["--out", "x"],
            "eval/training_env.py": ["record", "--checkpoint", "x.json", "--out", "x.npz"]}.get(path, [])
    parser = _run(path, argv).parser
    actions = list(parser._actions)
    for sub in (a for a in parser._actions if isinstance(a, argparse._SubParsersAction)):
        actions += [a for p in sub.choices.values() for a in p._actions]
    bare = [a.option_strings or a.dest for a in actions if a.type in (int, float)]
    assert not bare, f"{path}: {bare} take a bare int/float"


USAGE_ERRORS = [  # (script, argv, the flag named in the message)
    ("eval/training_env.py", ["record", "--checkpoint", "x.json", "--out", "x.npz", "--episodes", "0"], "--episodes"),
    ("eval/training_env.py", ["record", "--checkpoint", "x.json", "--out", "x.npz", "--steps", "-3"], "--steps"),
    ("eval/table.py", ["--episodes", "0"], "--episodes"),
    ("eval/table.py", ["--episodes", "-2"], "--episodes"),
    ("eval/table.py", ["--duration", "0"], "--duration"),
    ("eval/table.py", ["--duration", "-5"], "--duration"),
    ("eval/table.py", ["--workers", "0"], "--workers"),
    ("eval/table.py", ["--opponents", "-1"], "--opponents"),
    ("eval/table.py", ["--rhos", "0.5", "-0.1"], "--rhos"),
    ("eval/table.py", ["--gammas", "0.01"], "--gammas"),
    ("eval/table.py", ["--seed", "-1"], "--seed"),
    ("eval/table.py", ["--multi-agent", "--cars", "1"], "--cars"),
    ("eval/table.py", ["--duration", "nan"], "--duration"),
    ("eval/figures.py", ["--episodes", "0"], "--episodes"),
    ("eval/figures.py", ["--duration", "0"], "--duration"),
    ("eval/figures.py", ["--workers", "0"], "--workers"),
    ("eval/pareto.py", ["--episodes", "0"], "--episodes"),
    ("eval/pareto.py", ["--duration", "0"], "--duration"),
    ("eval/pareto.py", ["--workers", "-1"], "--workers"),
    ("eval/pareto.py", ["--resamples", "0"], "--resamples"),
    ("eval/stall_probe.py", ["x.csv", "--out", "x", "--before", "0"], "--before"),
    ("eval/stall_probe.py", ["x.csv", "--out", "x", "--horizons", "0"], "--horizons"),
    ("bench/bench_env.py", ["--steps", "0"], "--steps"),
    ("bench/bench_env.py", ["--repeats", "0"], "--repeats"),
    ("bench/bench_miqp.py", ["--repeat", "0"], "--repeat"),
    ("bench/bench_miqp.py", ["-n", "0"], "-n/--instances"),
    ("bench/bench_mpc.py", ["--steps", "0"], "--steps"),
    ("bench/bench_train.py", ["--compare", "HEAD", "--rounds", "0"], "--rounds"),
    ("bench/bench_vector.py", ["--workers", "0"], "--workers"),
    ("bench/bench_vector.py", ["--work-ms", "0"], "--work-ms"),
    ("eval/contacts.py", ["--heading-extent", "-1"], "--heading-extent"),
    ("eval/interventions.py", ["x.csv", "--workers", "0"], "--workers"),
    ("eval/interventions.py", ["x.csv", "--limit", "0"], "--limit"),
    ("eval/latency.py", ["--seconds", "0"], "--seconds"),
    ("eval/latency.py", ["--opponents", "-1"], "--opponents"),
    ("eval/multi_agent_races.py", ["--duration", "0"], "--duration"),
    ("eval/multi_agent_races.py", ["--workers", "0"], "--workers"),
    ("eval/parked_cars.py", ["--duration", "0"], "--duration"),
    ("eval/plot_training.py", ["run", "--columns", "0"], "--columns"),
    ("eval/plot_training.py", ["run", "--smoothing", "1"], "--smoothing"),
    ("eval/trajectories.py", ["record", "--out", "x.npz", "--episodes", "0"], "--episodes"),
    ("train/ppo.py", ["--n-envs", "0"], "--n-envs"),
    ("train/ppo.py", ["--total-steps", "0"], "--total-steps"),
    ("train/ppo.py", ["--learning-rate", "0"], "--learning-rate"),
    ("train/pasta.py", ["--n-steps", "0"], "--n-steps"),
    ("train/pasta.py", ["--total-steps", "0"], "--total-steps"),
    ("train/pasta.py", ["--n-envs", "0"], "--n-envs"),
    ("train/pasta.py", ["--torch-threads", "0"], "--torch-threads"),
    ("train/pasta.py", ["--preference-interval", "-1"], "--preference-interval"),
    ("eval/pasta_preference.py", ["probe", "--steps", "0"], "--steps"),
    ("eval/pasta_preference.py", ["respond", "--policy", "x", "--gammas", "0.01"], "--gammas"),
    ("eval/pasta_preference.py", ["respond", "--policy", "x", "--safety-weights", "0.95"], "--safety-weights"),
    ("eval/pasta_preference.py", ["push", "--policy", "x", "--rollouts", "0"], "--rollouts"),
    ("eval/pasta_preference.py", ["push", "--policy", "x", "--rho-max", "1.5"], "--rho-max"),
    ("eval/pasta_preference.py", ["floor", "--policy", "x", "--out", "o", "--floor", "0.01"], "--floor"),
    ("eval/pasta_preference.py", ["floor", "--policy", "x", "--out", "o", "--radius", "0"], "--radius"),
    ("eval/pasta_preference.py", ["floor", "--policy", "x", "--out", "o", "--safety-weight", "0.95"], "--safety-weight"),
]


@pytest.mark.parametrize(("path", "argv", "flag"), USAGE_ERRORS)
def test_out_of_range_numbers_are_usage_errors(path, argv, flag, parse_only, capsys):
    try:
        _script(path).main(argv)
    except _Parsed:
        pytest.fail(f"{path} {' '.join(argv)} parsed: the script would run")
    except SystemExit as exc:
        assert exc.code == 2
        err = capsys.readouterr().err
        assert "usage:" in err and f"error: argument {flag}" in err, err


VALID = [  # (script, argv, attribute, value): the values the flags mean still parse unchanged
    ("eval/table.py", ["--episodes", "1", "--duration", "0.5", "--workers", "1", "--opponents", "0", "--seed", "0"],
     "episodes", 1),
    ("eval/table.py", ["--gammas", "0.05", "1"], "gammas", [0.05, 1.0]),
    ("eval/table.py", ["--rhos", "0", "0.8"], "rhos", [0.0, 0.8]),
    ("eval/pareto.py", ["--duration", "12.5"], "duration", 12.5),
    ("bench/bench_env.py", ["--vector", "0"], "vector", 0),
    ("eval/plot_training.py", ["run", "--smoothing", "0"], "smoothing", 0.0),
    ("train/ppo.py", ["--save-every", "0"], "save_every", 0),
    ("train/pasta.py", ["--save-every", "0", "--total-steps", "16"], "total_steps", 16),
]


@pytest.mark.parametrize(("path", "argv", "attr", "value"), VALID)
def test_meaningful_numbers_still_parse(path, argv, attr, value, parse_only):
    assert getattr(_run(path, argv).namespace, attr) == value
