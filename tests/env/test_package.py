"""The package's public names: the environment and configuration classes, imported on first use."""

from __future__ import annotations

import pydoc
import subprocess
import sys

import sofar_env


def test_help_on_the_env_class_gives_the_full_spec():
    text = pydoc.render_doc(sofar_env.SOfARRaceEnv, renderer=pydoc.plaintext)
    assert "## Observation Space" in text and "## Rewards" in text and "get_state" in text


def test_every_public_name_resolves_and_is_listed():
    from sofar_env.config import EnvConfig
    from sofar_env.env import SOfARRaceEnv
    from sofar_env.multi_agent import SOfARParallelEnv
    from sofar_env.stack import StackConfig

    assert sofar_env.SOfARRaceEnv is SOfARRaceEnv and sofar_env.SOfARParallelEnv is SOfARParallelEnv
    assert sofar_env.EnvConfig is EnvConfig and sofar_env.StackConfig is StackConfig
    for name in sofar_env.__all__:
        assert getattr(sofar_env, name) is not None, name
        assert name in dir(sofar_env)
    assert "SOfARRaceEnv" in sofar_env.__all__ and "EnvConfig" in sofar_env.__all__


def test_unknown_names_raise_attribute_error():
    import pytest

    with pytest.raises(AttributeError, match="no attribute 'NoSuchEnv'"):
        sofar_env.NoSuchEnv  # noqa: B018


def test_import_stays_light():
    code = ("import sys, sofar_env; heavy = [m for m in ('sofar_env.env', 'sofar_env.config', 'casadi', 'pettingzoo') "
            "if m in sys.modules]; print(heavy)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
