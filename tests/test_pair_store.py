"""The pair store (``kernels.pairstore``): rings that the rows reuse change no bit.

A ring far shorter than the entries, with entries that its places cannot keep
long enough (their own places past the rings), against a store of one place per
near slot (``step(keep_pairs=True)``, the layout before the rings), with and
without friction, on one chunk and on three.
"""
import numpy as np
import pytest

from helpers import make_engine, tight_lattice
from mpdem.engine import cpu as engine
from mpdem.engine import pairstore
from mpdem.io.checkpoint import digest, gather_state
from mpdem.kernels.bundles import Near
from mpdem.kernels.pairstore import pair_places


def _run(mu, nchunk, keep, monkeypatch, ring=None):
    x, v, omega, fixed, L = tight_lattice(3)
    if ring:
        monkeypatch.setattr(engine, "FORCE_BLOCK", 1)
        monkeypatch.setattr(pairstore, "PAIR_RING", ring)
    eng = make_engine(x, v.copy(), omega.copy(), fixed.copy(), L=L, mu=mu, gravity=1.0,
                      gamma_t=10.0 if mu else 0.0)
    eng.set_chunks(nchunk)
    if ring:
        # blocks of a few rows, so that a short ring is allowed (at least 4 blocks)
        eng._scratch(int(np.diff(eng.lists.nbr_start[:eng.state.n_own + 1]).max()))
    seen = []
    for k in range(400):
        eng.step(keep_pairs=keep)
        if not keep and k % 50 == 0:
            n_own = eng.state.n_own
            per_chunk = max(np.diff(eng.lists.near_cstart[[c * n_own // nchunk for c in range(nchunk + 1)]]))
            far = int(np.sum(eng.lists.near_cpair[:eng.lists.k_near] >= nchunk * eng.store.pair_ring))
            seen.append((eng.store.pair_ring, int(per_chunk), far, eng.lists.k_near))
    s = eng.state
    return digest(gather_state(s)), s.f[:s.n_own].copy(), s.torque[:s.n_own].copy(), eng.contacts(), seen


@pytest.mark.parametrize("mu,nchunk", [(0.0, 1), (0.5, 1), (0.5, 3)])
def test_a_short_ring_gives_the_bits_of_a_place_per_slot(mu, nchunk, monkeypatch):
    kept = _run(mu, nchunk, True, monkeypatch)
    ringed = _run(mu, nchunk, False, monkeypatch, ring=16)
    ring, per_chunk, far, k_near = ringed[4][-1]
    # the ring was reused many times over, and some entries needed places of their own
    assert 4 * ring < per_chunk
    assert 0 < far < k_near // 2
    assert ringed[3] > 300                          # many contacts
    assert kept[0] == ringed[0]
    assert np.array_equal(kept[1].view(np.int64), ringed[1].view(np.int64))
    assert np.array_equal(kept[2].view(np.int64), ringed[2].view(np.int64))
    if mu:
        assert np.any(ringed[2] != 0.0)


def test_the_places_keep_every_entry_until_its_partner_reads_it():
    # rows of 3 computed entries; row j takes entry 1 of row j - 4 (odd j) or entry 2 of
    # row j - 6 (even j), which the pass reads after writing up to cstart[j] + width entries
    n, width, ring = 40, 3, 16
    cstart = np.zeros(n + 1, np.int64)
    cstart[1:] = np.cumsum([3] * (n - 5) + [0] * 5)
    back = [4 if j % 2 else 6 for j in range(n)]
    which = [1 if j % 2 else 2 for j in range(n)]
    # the last 5 rows compute nothing
    takes = [0 <= j - back[j] < n - 5 for j in range(n)]
    starts, links = [0], []
    for j in range(n):
        own = list(range(cstart[j], cstart[j + 1]))
        taken = [~int(cstart[j - back[j]] + which[j])] if takes[j] else []
        links += taken + own
        starts.append(len(links))
    k_near = int(cstart[n])
    near = Near(np.array(starts, np.int64), np.array(links, np.int32), cstart, np.zeros(k_near, np.int32),
                np.zeros(k_near, np.int32), np.zeros(k_near, np.int32))
    cpair = np.zeros(k_near, np.int32)
    plink = np.zeros(len(links), np.int32)
    places = pair_places(n, near, width, ring, 1, cpair, plink)
    kinds = set()
    for j in np.flatnonzero(takes):
        e = int(cstart[j - back[j]] + which[j])
        # the pass writes entries up to cstart[j] + width before row j sums; a ring place survives 16
        far = cstart[j] + width - e > ring
        assert (cpair[e] >= ring) == far
        kinds.add(bool(far))
    assert kinds == {True, False}
    # every other entry keeps its ring place
    taken = {~lk for lk in links if lk < 0}
    assert all(cpair[e] == e % ring for e in range(k_near) if e not in taken)
    assert places == ring + int(np.sum(cpair >= ring))
    assert len(set(cpair[cpair >= ring].tolist())) == int(np.sum(cpair >= ring))
    # the links name the places: a taken entry ~place, an own one place
    for k, lk in enumerate(links):
        e = lk if lk >= 0 else ~lk
        assert plink[k] == (cpair[e] if lk >= 0 else ~cpair[e])
