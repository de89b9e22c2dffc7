"""Controller presets through the environment: the spec, a closed loop, the shipped policies by name."""

import gymnasium as gym
import numpy as np
import pytest

import sofar_env  # noqa: F401
from sofar_agents import default_policy_path, load_policy
from sofar_env.stack import stack_preset


def test_preset_is_part_of_the_env_spec_and_config():
    env = gym.make("SOfAR-LagunaSeca-v0", stack="paper")
    assert env.spec.kwargs["stack"] == "paper"
    assert env.unwrapped.config.stack == stack_preset("paper")
    # other keys apply on top of the preset
    env2 = gym.make("SOfAR-LagunaSeca-v0", stack="paper", speed_factor=0.7)
    assert env2.unwrapped.config.stack.speed_factor == 0.7 and not env2.unwrapped.config.stack.follow
    with pytest.raises(ValueError, match="valid presets"):
        gym.make("SOfAR-LagunaSeca-v0", stack="papr")


def test_paper_preset_never_follows_where_the_default_stack_does():
    """Kentucky at rho 0.1: a slow car in a section too narrow to pass. The default stack follows it;
    the paper's Algorithm 1 has no following mode and attempts the pass."""
    counters = {}
    for stack in ("sofar", "paper"):
        env = gym.make("SOfAR-Kentucky-v0", stack=stack, rho=0.1).unwrapped
        env.reset(seed=3)
        for _ in range(150):
            _, _, terminated, truncated, _ = env.step(np.array([0.5], np.float32))
            if terminated or truncated:
                break
        counters[stack] = dict(env.stack.counters)
    assert counters["sofar"]["follow_steps"] > 0
    assert counters["paper"]["follow_steps"] == 0


@pytest.mark.parametrize("stack, scenario, name", [("sofar-1", "paper", "pasta_lagunaseca.json"),
                                                   ("paper", "paper", "pasta_lagunaseca_paper.json"),
                                                   ("sofar-1", "interactive", "pasta_lagunaseca_interactive.json"),
                                                   ("sofar", "paper", "pasta_lagunaseca_sofar17.json"),
                                                   ("sofar-17", "paper", "pasta_lagunaseca_sofar17.json"),
                                                   ("sofar-17", "interactive",
                                                    "pasta_lagunaseca_interactive_sofar17.json"),
                                                   ("sofar", "interactive-2",
                                                    "pasta_lagunaseca_interactive2_sofar17.json"),
                                                   ("sofar-13", "paper", "pasta_lagunaseca_sofar13.json"),
                                                   ("sofar-13", "interactive",
                                                    "pasta_lagunaseca_interactive_sofar13.json"),
                                                   ("sofar-6", "paper", "pasta_lagunaseca_sofar6.json"),
                                                   ("sofar-6", "interactive",
                                                    "pasta_lagunaseca_interactive_sofar6.json"),
                                                   ("sofar-4", "paper", "pasta_lagunaseca_sofar4.json"),
                                                   ("sofar-4", "interactive",
                                                    "pasta_lagunaseca_interactive_sofar4.json")])
def test_shipped_policies_load_by_name(stack, scenario, name):
    import gymnasium as gym

    path = default_policy_path(stack=stack, scenario=scenario)
    assert path.name == name
    policy = load_policy(path)
    suffix = {"interactive": "-Interactive-v0", "interactive-2": "-Interactive-v1"}.get(scenario, "-v0")
    env = gym.make(f"SOfAR-LagunaSeca{suffix}", stack=stack)
    obs, _ = env.reset(seed=0)
    gamma = float(np.asarray(policy(obs)).reshape(-1)[0])
    assert 0.05 <= gamma <= 1.0
    env.close()


def test_the_default_controller_has_its_own_policies():
    """"sofar" looks up the default's version; a preset without a trained policy gets none."""
    for scenario in ("paper", "interactive"):
        default = default_policy_path(stack="sofar", scenario=scenario)
        assert default == default_policy_path(stack="sofar-17", scenario=scenario)
        assert default not in (default_policy_path(stack="sofar-13", scenario=scenario),
                               default_policy_path(stack="sofar-6", scenario=scenario),
                               default_policy_path(stack="sofar-4", scenario=scenario),
                               default_policy_path(stack="sofar-1", scenario=scenario))
    # each version of the interactive world has its own policy (same recipe and seed, trained in that world)
    assert default_policy_path(stack="sofar", scenario="interactive-2") != default_policy_path(stack="sofar",
                                                                                              scenario="interactive")
    with pytest.raises(ValueError, match="no shipped PASTA policy"):
        default_policy_path(stack="sofar-13", scenario="interactive-2")
    with pytest.raises(ValueError, match="no shipped PASTA policy"):
        default_policy_path(stack="sofar-3")
    with pytest.raises(ValueError, match="no shipped PASTA policy"):
        default_policy_path(stack="sofar", scenario="dynamic")


def test_no_shipped_policy_for_an_unknown_combination():
    with pytest.raises(ValueError, match="no shipped PASTA policy"):
        default_policy_path(stack="paper", scenario="moon")
