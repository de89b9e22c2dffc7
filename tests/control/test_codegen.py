"""CasADi -> C compilation: same numbers, cache hit on the second call, fallbacks never raise."""

import casadi as ca
import numpy as np
import pytest

from sofar_env.control.codegen import compile_function, default_cache_dir


def _function(name="sofar_test_fn", power=3):
    x = ca.SX.sym("x", 2)
    return ca.Function(name, [x], [ca.vertcat(ca.sin(x[0]) * x[1] ** power, ca.exp(-x[1]))])


def test_compiled_function_is_cached_and_gives_the_same_numbers(tmp_path):
    func = _function()
    compiled, info = compile_function(func, tmp_path)
    if not info.compiled:
        pytest.skip(f"no working C compiler: {info.message}")
    assert info.built_now and info.path.endswith(".so")
    again, info2 = compile_function(_function(), tmp_path)
    assert info2.compiled and not info2.built_now and info2.path == info.path
    x = np.array([0.3, -1.7])
    np.testing.assert_allclose(np.asarray(again(x)), np.asarray(func(x)), rtol=1e-15)
    # a different definition (same name) gets its own library
    _, info3 = compile_function(_function(power=2), tmp_path)
    assert info3.built_now and info3.path != info.path
    assert not list(tmp_path.glob(".build_*"))  # no temporary build directory left behind


def test_disabled_or_without_compiler_returns_the_casadi_function(tmp_path, monkeypatch):
    func = _function()
    same, info = compile_function(func, tmp_path, enabled=False)
    assert same is func and not info.compiled
    monkeypatch.setenv("CC", str(tmp_path / "no_such_compiler"))
    same, info = compile_function(_function("sofar_test_fn_nocc"), tmp_path)
    assert not info.compiled and "failed" in info.message
    assert not list(tmp_path.glob("*.so"))


def test_cache_directory_follows_the_environment(tmp_path, monkeypatch):
    monkeypatch.setenv("SOFAR_CACHE_DIR", str(tmp_path / "a"))
    assert default_cache_dir() == tmp_path / "a"
    monkeypatch.delenv("SOFAR_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert default_cache_dir() == tmp_path / "xdg" / "sofar"
