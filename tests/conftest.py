import pytest

from helpers import make_engine
from mpdem.kernels.calls import Bound

# every 16th kernel call through an overload numba chose compares its argument types with the chosen ones
Bound.check = 16


@pytest.fixture
def engine_factory():
    return make_engine
