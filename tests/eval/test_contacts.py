"""eval/contacts.py: replay a collision of the multi-agent table to its first contact."""

from __future__ import annotations

import importlib.util
import sys
from dataclasses import replace
from pathlib import Path

import pytest

from sofar_agents.evaluation.multi_agent import RaceResult

ROOT = Path(__file__).resolve().parents[2]


def _script():
    spec = importlib.util.spec_from_file_location("eval_contacts", ROOT / "eval" / "contacts.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclass looks its module up there
    spec.loader.exec_module(module)
    return module


def _row(**kw) -> RaceResult:
    base = dict(track="Monza", strategy="gamma=0.50", policy_id="", seed=2286877623, cars=4, duration=200.0,
                stack="sofar-6", scenario="paper", overtakes=0, collided=2, off_track=0, stalled=0, success=2,
                driven=0.1, mean_gamma=0.5, speed_factors="", wall_time=0.0, opponents=0)
    base.update(kw)
    return RaceResult(**base)


def test_a_contact_at_a_chicane_with_the_cars_turned_is_inside_the_aligned_ellipses_clear_set():
    """Monza, a race of an earlier multi-agent table (gamma 0.5): without the heading-aware barrier, at the
    first chicane car 0 touches car 2, both turned 0.4-0.7 rad to the track at 10-17 m/s; the barrier, whose
    ellipse assumes aligned cars, has h > 0 there. With the multi-car default (the ellipse widened by both
    cars' rotation) the race has no contact. The controller is ``"sofar-6"``, whose own barrier is the aligned
    one (the default ``"sofar-13"`` widens it itself)."""
    script = _script()
    contact = script.first_contact(_row(), {"heading_extent": 0.0})
    assert contact is not None
    assert contact.time == pytest.approx(11.3) and contact.cars == (0, 2)
    assert contact.h_aligned > 0.0 and min(abs(e) for e in contact.headings) > 0.3
    assert contact.h == contact.h_aligned  # the cars' own barrier is the aligned one here
    table = script.format_contacts([(_row(), contact), (replace(_row(), seed=1), None)])
    assert "| Monza | 2286877623 | gamma=0.50 | 11.3 | 0, 2 |" in table
    assert "no contact with this code" in table
    assert "clear (h >= 0) at 1 of them with the aligned ellipse and at 1 with the cars' own barrier" in table
    assert script.first_contact(_row()) is None
