"""Command-line help: plain text (no reStructuredText markup), and the controller presets and worlds listed
from their registries (``STACK_PRESETS``, ``SCENARIOS``), never by hand."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from sofar_agents.cli import plain_text
from sofar_env.scenarios import SCENARIOS
from sofar_env.stack.config import STACK_PRESETS

ROOT = Path(__file__).resolve().parents[1]
RST = re.compile(r"``|:[a-z]+:`|(?<![\w`])`[^`\s][^`]*`")

SCRIPTS = {  # script: its options that name a preset or a world
    "train/pasta.py": ("--stack", "--scenario"),
    "eval/table.py": ("--stack", "--scenario"),
    "eval/figures.py": ("--stack", "--scenario"),
    "eval/pareto.py": ("--stack", "--scenario"),
    "bench/bench_env.py": ("--stack", "--scenario"),
    "bench/bench_train.py": ("--scenario",),
}


def _help(script: str) -> dict[str, str]:
    text = subprocess.run([sys.executable, script, "--help"], cwd=ROOT, capture_output=True, text=True, timeout=120,
                          check=True, env={**os.environ, "COLUMNS": "2000"}).stdout
    entries = ["--" + " ".join(e.split()) for e in text.split("\n  --")[1:]]  # one per option, unwrapped
    return {e.split()[0].rstrip(","): e for e in entries} | {"": text}


def test_plain_text_drops_the_markup() -> None:
    assert plain_text("see :class:`~sofar_env.tracks.Track` and :func:`sofar_env.parallel_env`") == (
        "see Track and sofar_env.parallel_env")
    assert plain_text(":meth:`the step <sofar_env.env.SOfARRaceEnv.step>`") == "the step"
    assert plain_text('pass ``--out X``, ``"stch"`` or `x`') == 'pass --out X, "stch" or x'
    assert plain_text("no markup: a [0.05, 1] box, 2 * x") == "no markup: a [0.05, 1] box, 2 * x"


@pytest.mark.parametrize("script", sorted(SCRIPTS))
def test_presets_and_worlds_come_from_the_registries(script: str) -> None:
    lines = _help(script)
    for option in SCRIPTS[script]:
        names = STACK_PRESETS if option == "--stack" else SCENARIOS
        for name in names:
            assert re.search(rf"(?<![\w-]){re.escape(name)}(?![\w-])", lines[option]), (script, option, name)
    assert not RST.search(lines[""]), RST.search(lines[""])  # plain text, no reStructuredText


def test_training_help_is_plain_text() -> None:
    for script in ("train/pasta.py", "train/ppo.py", "eval/plot_training.py"):
        text = _help(script)[""]
        assert not RST.search(text), (script, RST.search(text))
