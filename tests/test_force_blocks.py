"""The force pass's blocks of rows (``engine.FORCE_BLOCK``, ``forces._rows``) change no bit:
blocks of a few rows and blocks of hundreds give the same trajectory, with and without friction."""
import numpy as np
import pytest

from helpers import make_engine
from mpdem import engine
from mpdem.io.checkpoint import digest, gather_state
from mpdem.kernels.bundles import Scratch
from mpdem.kernels.forces import contact_forces_serial


@pytest.mark.parametrize("mu", [0.0, 0.5])
def test_blocks_of_any_size_give_the_same_bits(mu, monkeypatch):
    # a jittered cubic lattice a little tighter than touching: some 3 contacts a sphere from the start
    g = np.random.default_rng(3)
    a, m = 0.997, 9
    L = a * m
    x = a * (np.stack(np.meshgrid(*(np.arange(m),) * 3, indexing="ij"), -1).reshape(-1, 3) + 0.5)
    x += 0.004 * g.standard_normal(x.shape)
    x[:, 2] += 0.5
    n = len(x)
    v = 0.05 * g.standard_normal(x.shape)
    omega = 0.1 * g.standard_normal(x.shape)
    # the lowest layer frozen: rows the pass skips, and partners of infinite mass
    fixed = (x[:, 2] < a).astype(np.uint8)
    runs = []
    for block in (1, engine.FORCE_BLOCK):
        monkeypatch.setattr(engine, "FORCE_BLOCK", block)
        eng = make_engine(x, v.copy(), omega.copy(), fixed.copy(), L=L, mu=mu, gravity=1.0,
                          gamma_t=10.0 if mu else 0.0)
        if block == 1:
            # room for the longest list only: a block is the few rows whose computed entries fit
            eng._scratch(int(np.diff(eng.nbr_start[:eng.state.n_own + 1]).max()))
        eng.advance(500)
        room = eng._found.shape[1]
        assert room < 40 if block == 1 else room == max(block, eng._width)
        assert eng.contacts() > n // 2          # the law ran on many contacts a block
        runs.append((digest(gather_state(eng.state)), eng.state.f[:eng.state.n_own].copy(),
                     eng.state.torque[:eng.state.n_own].copy()))
    assert runs[0][0] == runs[1][0]
    assert np.array_equal(runs[0][1].view(np.int64), runs[1][1].view(np.int64))
    assert np.array_equal(runs[0][2].view(np.int64), runs[1][2].view(np.int64))
    if mu:
        assert np.any(runs[0][2] != 0.0)


def test_scratch_narrower_than_a_row_is_an_error_not_an_endless_loop():
    g = np.random.default_rng(4)
    a, m = 0.997, 5
    x = a * (np.stack(np.meshgrid(*(np.arange(m),) * 3, indexing="ij"), -1).reshape(-1, 3) + 0.5)
    x += 0.004 * g.standard_normal(x.shape)
    eng = make_engine(x, L=a * m, mu=0.5, gamma_t=10.0)
    eng.advance(2)
    longest = int(np.diff(eng.near_cstart[:eng.state.n_own + 1]).max())
    assert longest >= 2
    w = longest - 1
    narrow = Scratch(np.zeros(1), np.zeros(1, np.int64), np.zeros((1, w, 3), np.int32), np.zeros((1, w, 4)),
                     np.zeros((1, w, 9)))
    with pytest.raises(ValueError, match="narrower"):
        contact_forces_serial(eng.state.n_own, eng._particles(), eng._near(), eng._slots(), eng._epoch + 1,
                              eng._box(), eng.law, True, narrow)
