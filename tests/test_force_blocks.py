"""The force pass's blocks of rows (``engine.FORCE_BLOCK``, ``forces._rows``) change no bit:
blocks of a few rows and blocks of hundreds give the same trajectory, with and without friction."""
import numpy as np
import pytest

from helpers import make_engine, tight_lattice
from mpdem.engine import cpu as engine
from mpdem.io.checkpoint import digest, gather_state
from mpdem.kernels.bundles import Scratch
from mpdem.kernels.forces import contact_forces_serial


@pytest.mark.parametrize("mu", [0.0, 0.5])
def test_blocks_of_any_size_give_the_same_bits(mu, monkeypatch):
    x, v, omega, fixed, L = tight_lattice(3)
    n = len(x)
    runs = []
    for block in (1, engine.FORCE_BLOCK):
        monkeypatch.setattr(engine, "FORCE_BLOCK", block)
        eng = make_engine(x, v.copy(), omega.copy(), fixed.copy(), L=L, mu=mu, gravity=1.0,
                          gamma_t=10.0 if mu else 0.0)
        if block == 1:
            # room for the longest list only: a block is the few rows whose computed entries fit
            eng._scratch(int(np.diff(eng.lists.nbr_start[:eng.state.n_own + 1]).max()))
        eng.advance(500)
        room = eng._work.found.shape[1]
        assert room >= eng.lists.longest() and (room < 40 if block == 1 else room >= block)
        assert eng.contacts() > n // 2          # the law ran on many contacts a block
        runs.append((digest(gather_state(eng.state)), eng.state.f[:eng.state.n_own].copy(),
                     eng.state.torque[:eng.state.n_own].copy()))
    assert runs[0][0] == runs[1][0]
    assert np.array_equal(runs[0][1].view(np.int64), runs[1][1].view(np.int64))
    assert np.array_equal(runs[0][2].view(np.int64), runs[1][2].view(np.int64))
    if mu:
        assert np.any(runs[0][2] != 0.0)


def test_scratch_narrower_than_a_row_is_an_error_not_an_endless_loop():
    x, _, _, _, L = tight_lattice(4, m=5)
    eng = make_engine(x, L=L, mu=0.5, gamma_t=10.0)
    eng.advance(2)
    longest = int(np.diff(eng.lists.near_cstart[:eng.state.n_own + 1]).max())
    assert longest >= 2
    w = longest - 1
    narrow = Scratch(np.zeros(1), np.zeros(1, np.int64), np.zeros((1, w, 3), np.int32), np.zeros((1, w, 4)),
                     np.zeros((1, w, 9)))
    with pytest.raises(ValueError, match="narrower"):
        contact_forces_serial(eng.state.n_own, eng._particles(), eng.lists.near(), eng.lists.slots(eng.store.pair),
                              eng._epoch + 1, eng.lists.box(), eng.law, True, narrow)
