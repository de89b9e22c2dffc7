"""Command-line options generated from documented dataclasses."""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from typing import Annotated

import pytest

from sofar_agents import PASTAConfig
from sofar_agents.cli import add_dataclass_options, check_dataclass_options, dataclass_field_docs
from sofar_agents.cli_types import (finite_float, float_in, gamma_value, int_at_least, nonneg_float, nonneg_int,
                                    positive_float, positive_int)


@dataclass(frozen=True)
class _Options:
    """Test options."""

    speed: float = 1.5
    """Target speed
    of the test [m/s]."""
    name: str | None = None
    """Optional name."""
    sizes: tuple[int, ...] = (2, 3)
    """Layer sizes."""
    verbose: bool = True
    undocumented: int = 0


def test_field_docs() -> None:
    docs = dataclass_field_docs(_Options)
    assert docs == {"speed": "Target speed of the test [m/s].", "name": "Optional name.", "sizes": "Layer sizes."}
    assert "learning_rate" in dataclass_field_docs(PASTAConfig)
    assert dataclass_field_docs(int) == {}  # not a dataclass: nothing found


def test_options_only_carry_given_values() -> None:
    parser = argparse.ArgumentParser()
    add_dataclass_options(parser, _Options, "test")
    ns = parser.parse_args(["--speed", "2", "--sizes", "4", "5", "--no-verbose"])
    assert (ns.speed, ns.sizes, ns.verbose, ns.name, ns.undocumented) == (2.0, [4, 5], False, None, None)
    assert "Target speed of the test [m/s]. (default: 1.5)" in " ".join(parser.format_help().split())


# Every number of a command line is checked by its argument type (sofar_agents.cli_types): 0 or a negative
# count, a non-finite or out-of-range value is a usage error (exit status 2), never "unset" or a silent default.
TYPE_CASES = [  # (type, text, value or None for a usage error)
    (positive_int, "3", 3), (positive_int, "1", 1), (positive_int, "0", None), (positive_int, "-2", None),
    (positive_int, "1.5", None), (positive_int, "x", None),
    (nonneg_int, "0", 0), (nonneg_int, "-1", None),
    (int_at_least(2), "2", 2), (int_at_least(2), "1", None),
    (positive_float, "0.5", 0.5), (positive_float, "0", None), (positive_float, "-1", None),
    (positive_float, "nan", None), (positive_float, "inf", None),
    (nonneg_float, "0", 0.0), (nonneg_float, "-0.1", None),
    (finite_float, "-3.5", -3.5), (finite_float, "nan", None),
    (float_in(0.0, 1.0, high_open=True), "0", 0.0), (float_in(0.0, 1.0, high_open=True), "1", None),
    (float_in(0.0, 1.0, low_open=True), "1", 1.0), (float_in(0.0, 1.0, low_open=True), "0", None),
    (gamma_value, "0.05", 0.05), (gamma_value, "1", 1.0), (gamma_value, "0.01", None), (gamma_value, "1.5", None),
]


@pytest.mark.parametrize(("kind", "text", "value"), TYPE_CASES)
def test_argument_types(kind, text, value) -> None:
    if value is None:
        with pytest.raises(argparse.ArgumentTypeError, match="got"):
            kind(text)
    else:
        assert kind(text) == value and type(kind(text)) is type(value)


@dataclass(frozen=True)
class _Counts:
    """Options with argument types."""

    episodes: Annotated[int, positive_int] = 5
    """Episodes."""
    rate: Annotated[float, positive_float] | None = None
    """A rate."""
    sizes: Annotated[tuple[int, ...], positive_int] = (2,)
    """Sizes."""
    seed: int = 0
    """Seed (an int without its own type: >= 0)."""
    scale: float = 1.0
    """Scale (a float without its own type: finite)."""


GENERATED_CASES = [  # (class, argv, error text or None when it parses)
    (_Counts, ["--episodes", "1", "--rate", "0.5", "--sizes", "3", "4", "--seed", "0", "--scale", "-2"], None),
    (_Counts, ["--episodes", "0"], "argument --episodes: must be a whole number >= 1, got '0'"),
    (_Counts, ["--episodes", "-2"], "argument --episodes"),
    (_Counts, ["--rate", "0"], "argument --rate: must be a number > 0"),
    (_Counts, ["--sizes", "3", "0"], "argument --sizes"),
    (_Counts, ["--seed", "-1"], "argument --seed"),
    (_Counts, ["--scale", "nan"], "argument --scale: expected a finite number"),
    (PASTAConfig, ["--n-steps", "0"], "argument --n-steps"),
    (PASTAConfig, ["--learning-rate", "0"], "argument --learning-rate"),
    (PASTAConfig, ["--discount", "0"], "argument --discount: must lie in (0, 1]"),
    (PASTAConfig, ["--kappa", "1"], "argument --kappa"),
    (PASTAConfig, ["--hidden-sizes", "64", "0"], "argument --hidden-sizes"),
    (PASTAConfig, ["--target-kl", "-0.01"], "argument --target-kl"),
    (PASTAConfig, ["--n-steps", "8", "--target-kl", "0.02", "--hidden-sizes", "8", "8"], None),
]


@pytest.mark.parametrize(("cls", "argv", "error"), GENERATED_CASES)
def test_generated_options_check_numbers(cls, argv, error, capsys) -> None:
    parser = argparse.ArgumentParser()
    add_dataclass_options(parser, cls, "test")
    if error is None:
        parser.parse_args(argv)
        return
    with pytest.raises(SystemExit) as exc:
        parser.parse_args(argv)
    assert exc.value.code == 2 and error in capsys.readouterr().err


def test_dataclass_checks_become_usage_errors(capsys) -> None:
    parser = argparse.ArgumentParser()
    assert check_dataclass_options(parser, PASTAConfig, {"mu_min": 0.2}).mu_min == 0.2
    with pytest.raises(SystemExit) as exc:
        check_dataclass_options(parser, PASTAConfig, {"mu_min": 5.0, "mu_max": 1.0})
    assert exc.value.code == 2 and "mu_min <= mu_max" in capsys.readouterr().err
