"""The objectives' registry (sofar_env.configs.objectives) is the one definition of the reward vector: its order,
terms, default weights and reference preference; the environments, RewardWeights and the training scripts
read it."""

from __future__ import annotations

import ast
import dataclasses
from pathlib import Path

import numpy as np

from sofar_env import config as env_config
from sofar_env.configs.objectives import OBJECTIVE_NAMES, OBJECTIVES, REFERENCE_PREFERENCE, StepOutcome, objective
from sofar_env.rewards import (barrier_margin_term, gamma_smoothness_term, overtake_term, progress_term,
                               reward_vector, safety_term)

ROOT = Path(__file__).resolve().parents[2]


def test_the_registry_keeps_the_values_of_the_reward_vector():
    assert OBJECTIVE_NAMES == env_config.OBJECTIVE_NAMES == ("safety", "overtakes", "progress", "barrier_margin",
                                                             "gamma_smoothness")
    assert REFERENCE_PREFERENCE == (0.31, 0.45, 0.05, 0.04, 0.15)
    weights = env_config.RewardWeights()
    assert [f.name for f in dataclasses.fields(weights)] == list(OBJECTIVE_NAMES)
    assert weights.as_array().tolist() == [10.0, 1.0, 0.05, 0.5, 0.1] == [o.default_weight for o in OBJECTIVES]
    assert objective("progress") is OBJECTIVES[2]
    for o in OBJECTIVES:
        assert o.bounds[0] <= o.bounds[1] and o.doc


def test_reward_vector_evaluates_every_term_of_the_registry_as_before():
    rng = np.random.default_rng(7)
    for _ in range(200):
        kw = dict(collision=bool(rng.integers(2)), off_track=bool(rng.integers(2)), overtakes=int(rng.integers(3)),
                  progress=float(rng.normal(5, 3)), profile_speed=float(rng.uniform(0, 80)), dt=0.1,
                  barrier_slack=float(rng.exponential(0.1)), min_h=float(rng.normal(0.5, 1.0)),
                  gamma=float(rng.uniform(0.05, 1)), previous_gamma=float(rng.uniform(0.05, 1)))
        expected = np.array([safety_term(kw["collision"], kw["off_track"]), overtake_term(kw["overtakes"]),
                             progress_term(kw["progress"], kw["profile_speed"], kw["dt"]),
                             barrier_margin_term(kw["barrier_slack"], kw["min_h"]),
                             gamma_smoothness_term(kw["gamma"], kw["previous_gamma"])])
        got = reward_vector(**kw)
        assert got.dtype == np.float64 and np.array_equal(got, expected)
        step = StepOutcome(**kw)
        for o, value in zip(OBJECTIVES, got):
            assert o.term(step) == value
            assert o.bounds[0] <= value <= o.bounds[1], o.name


def test_the_training_scripts_keep_no_copy_of_the_reference_preference():
    for script in ("pasta.py", "ppo.py"):
        tree = ast.parse((ROOT / "train" / script).read_text(encoding="utf-8"))
        assigned = {t.id for node in tree.body if isinstance(node, (ast.Assign, ast.AnnAssign))
                    for t in (node.targets if isinstance(node, ast.Assign) else [node.target])
                    if isinstance(t, ast.Name)}
        imported = {a.asname or a.name for node in tree.body if isinstance(node, ast.ImportFrom)
                    and node.module == "sofar_env.configs.objectives" for a in node.names}
        assert "REFERENCE_PREFERENCE" not in assigned and "REFERENCE_PREFERENCE" in imported, script
