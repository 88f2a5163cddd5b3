"""Kernel calls through the overload numba chose (``kernels.calls.Bound``)."""
import numpy as np
import pytest
from numba import njit

from mpdem.kernels.bundles import Particles
from mpdem.kernels.calls import Bound


@njit(cache=False)
def _scale_x(particles, factor):
    x = particles.x
    for i in range(x.shape[0]):
        for k in range(x.shape[1]):
            x[i, k] *= factor
    return x.shape[0]


def _particles(n, dtype=np.float64):
    return Particles(np.arange(3 * n, dtype=dtype).reshape(n, 3), *(np.zeros((n, 3)) for _ in range(4)),
                     np.zeros(n, np.uint8))


def test_bound_call_is_the_kernel_call():
    k = Bound(_scale_x)
    p = _particles(4)
    assert k(p, 2.0) == 4                    # the first call: numba's dispatch
    assert k._entry is not None              # then the compiled entry point
    q = _particles(7)                        # new arrays of the same types: no reset needed
    assert k(q, 3.0) == 7
    np.testing.assert_array_equal(p.x, 2.0 * np.arange(12.0).reshape(4, 3))
    np.testing.assert_array_equal(q.x, 3.0 * np.arange(21.0).reshape(7, 3))


def test_bound_check_catches_a_changed_type(monkeypatch):
    monkeypatch.setattr(Bound, "check", 3)
    k = Bound(_scale_x)
    k(_particles(2), 2.0)
    k(_particles(2), 2.0)
    k(_particles(2), 2.0)
    with pytest.raises(TypeError, match="_scale_x: argument types changed"):
        k(_particles(2, np.float32), 2.0)
    # after a reset numba chooses (compiles) again, and the new types are the bound ones
    k.reset()
    p = _particles(2, np.float32)
    assert k(p, 0.5) == 2
    assert p.x.dtype == np.float32 and p.x[1, 2] == np.float32(2.5)
    assert k(_particles(3, np.float32), 1.0) == 3


def test_bound_check_takes_numbas_types_not_fingerprints(monkeypatch):
    # a numpy int64 where a Python int was: another fingerprint, the same numba type (int64)
    monkeypatch.setattr(Bound, "check", 1)
    k = Bound(_scale_x)
    p = _particles(2)
    k(p, 2)
    assert k(p, np.int64(3)) == 2
    np.testing.assert_array_equal(p.x, 6.0 * np.arange(6.0).reshape(2, 3))
    with pytest.raises(TypeError, match="argument types changed"):
        k(p, 2.0)


def test_bound_checks_in_the_test_suite():
    # conftest turns the check on, so the engine's steps in the tests compare the types
    assert Bound.check > 0


def test_bound_plain_function():
    # NUMBA_DISABLE_JIT makes kernels plain functions: Bound calls them
    k = Bound(_scale_x.py_func)
    p = _particles(2)
    assert k(p, 2.0) == 2 and k(p, 2.0) == 2
    assert p.x[1, 0] == 12.0


def _column():
    g = np.arange(3) + 0.5
    bed = [[i, j, 0.0] for j in g for i in g]
    mob = [[i + 0.01 * k, j, 0.98 * k] for k in range(1, 5) for j in g for i in g]
    return np.array(mob + bed), np.r_[np.zeros(len(mob)), np.ones(len(bed))].astype(np.uint8)


def _by_id(eng):
    s = eng.state
    order = np.argsort(s.id[:s.n_own])
    return s.x[order], s.v[order], s.omega[order]


def test_engine_rebinds_at_reallocation(engine_factory):
    # a state grown between steps (new arrays, then a rebuild) runs on through newly chosen
    # overloads, bit for bit as the run that did not grow
    x, fixed = _column()
    runs = [engine_factory(x, fixed=fixed, L=3.0, mu=0.5, gamma_t=10.0, gravity=1.0) for _ in range(2)]
    for eng in runs:
        eng.advance(20)
        assert eng._kernels.contact_forces._entry is not None
    grown = runs[1]
    grown.state.grow(2 * grown.state.capacity)
    grown.rebuild()
    assert grown._kernels.contact_forces._entry is None and grown._kernels.kick._entry is None
    runs[0].rebuild()
    for eng in runs:
        eng.advance(200)
    assert grown._kernels.contact_forces._entry is not None
    for a, b in zip(*(_by_id(e) for e in runs)):
        np.testing.assert_array_equal(a, b)
