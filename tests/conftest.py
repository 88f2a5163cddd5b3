import numpy as np
import pytest

from mpdem import build
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


def settled_table(path, depth=1e-3):
    """A 6 d x 6 d bed (36 spheres on a unit grid at z = 0) with a column of
    6 mobile spheres on each, each sphere overlapping the one below by ``depth`` [d].

    Returns the numbers of mobile (216) and bed (36) spheres."""
    g = np.arange(6) + 0.5
    bed = np.array([[i, j, 0.0] for j in g for i in g])
    mob = np.array([[i, j, (1 - depth) * k] for k in range(1, 7) for j in g for i in g])
    x = np.concatenate([mob, bed])
    fixed = np.r_[np.zeros(len(mob)), np.ones(len(bed))].astype(np.uint8)
    build.write_table(path, np.arange(1, len(x) + 1), x, fixed=fixed)
    return len(mob), len(bed)
