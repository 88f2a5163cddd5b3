import pytest

from helpers import make_engine


@pytest.fixture
def engine_factory():
    return make_engine
