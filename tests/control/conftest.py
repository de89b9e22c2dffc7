import pytest


@pytest.fixture(scope="session")
def cache_dir(tmp_path_factory):
    """A private cache of compiled stage functions, shared by the controller tests of one session."""
    return str(tmp_path_factory.mktemp("sofar_cache"))
