"""Command-line options generated from documented dataclasses."""

from __future__ import annotations

import argparse
from dataclasses import dataclass

from sofar_agents import PASTAConfig
from sofar_agents.cli import add_dataclass_options, dataclass_field_docs


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
