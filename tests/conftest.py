import numpy as np
import pytest

from mpdem.config import gamma_n_from_epsilon
from mpdem.decomp import Domain
from mpdem.engine import Engine, Physics
from mpdem.state import State


def make_engine(x, v=None, omega=None, fixed=None, L=10.0, **phys):
    """An Engine over the given particles (ids 0..n-1) with set-up done."""
    k_n = phys.pop("k_n", 2e5)
    eps = phys.pop("epsilon", 0.88)
    defaults = dict(k_n=k_n, k_t=2 * k_n / 7, gamma_n=gamma_n_from_epsilon(eps, k_n),
                    gamma_t=0.0, mu=0.0, dt=1e-4 * np.sqrt(2e5 / k_n), gravity=0.0)
    defaults.update(phys)
    x = np.asarray(x, float)
    st = State(np.arange(len(x)), x, v, omega, fixed, L, L)
    eng = Engine(st, Physics(**defaults), Domain(None))
    eng.setup()
    return eng


@pytest.fixture
def engine_factory():
    return make_engine
