import pytest

from sofar_env.tracks import Track


@pytest.fixture(scope="session")
def tracks():
    return {name: Track.load(name) for name in ("LagunaSeca", "Monza", "Indianapolis", "Kentucky")}
