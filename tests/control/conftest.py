import importlib
import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[2] / "bench"


@pytest.fixture(scope="session")
def cache_dir(tmp_path_factory):
    """A private cache of compiled stage functions, shared by the controller tests of one session."""
    return str(tmp_path_factory.mktemp("sofar_cache"))


@pytest.fixture(scope="module")
def bench():
    """``bench/bench_qp_backends.py`` as a module: the closed-loop QP recorder and the backends' comparison."""
    sys.path.insert(0, str(BENCH))
    try:
        yield importlib.import_module("bench_qp_backends")
    finally:
        sys.path.remove(str(BENCH))
