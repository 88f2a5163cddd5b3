"""The near lists (kernels/near.py): the force kernel's entries within 1 + near_skin.

They must keep every pair that can touch before the next filtering and change
no bit of a trajectory, frictionless or frictional, on one chunk or several.
"""
import dataclasses
import math

import numpy as np
import pytest

from helpers import make_engine
from mpdem.build import insert_random, rng
from mpdem.io.checkpoint import digest, gather_state
from mpdem.kernels.history import slot_of


def _pour(n=300, L=6.0, seed=5):
    return insert_random(rng(seed, 1), n, L, L, 0.5, 0.5 + n * (math.pi / 6) / (L * L * 0.3)), L


def test_near_lists_keep_exactly_the_list_entries_within_reach_in_partner_order():
    x, L = _pour()
    eng = make_engine(x, L=L, mu=0.5, gravity=1.0, skin=0.4, near_skin=0.1)
    eng.set_chunks(3)
    s = eng.state
    r2_near = 1.1 ** 2
    # each slot's computing row and partner, from the lists
    hist_rows = np.full(len(eng.lists.hist), -1)
    partner = np.full(len(eng.lists.hist), -1)
    for i in range(s.n_own):
        for k in range(eng.lists.nbr_start[i], eng.lists.nbr_start[i + 1]):
            if eng.lists.link[k] >= 0:
                hist_rows[eng.lists.link[k]], partner[eng.lists.link[k]] = i, eng.lists.nbr_list[k]
    assert np.all(hist_rows >= 0)
    kept = 0
    for i in range(s.n_own):
        full = range(eng.lists.nbr_start[i], eng.lists.nbr_start[i + 1])
        near = eng.lists.near_link[eng.lists.near_start[i]:eng.lists.near_start[i + 1]]
        d = s.x[eng.lists.nbr_list[full.start:full.stop]] - s.x[i]
        d[:, :2] -= L * np.round(d[:, :2] / L)
        within = (d ** 2).sum(axis=1) < r2_near
        if s.fixed[i]:
            assert len(near) == 0
            continue
        # the near entries are the list entries within reach, in the lists' (partner-id) order
        want = [eng.lists.link[k] for k, w in zip(full, within) if w]
        got = [eng.lists.near_cslot[slot_of(lk)] for lk in near]
        assert got == [slot_of(lk) for lk in want]
        # computed stays computed, taken stays taken
        assert [lk < 0 for lk in near] == [lk < 0 for lk in want]
        kept += len(near)
        # a row's computed near entries are its own slots' partners
        for e in range(eng.lists.near_cstart[i], eng.lists.near_cstart[i + 1]):
            g = eng.lists.near_cslot[e]
            assert hist_rows[g] == i and eng.lists.near_cj[e] == partner[g]
    assert 0 < kept < eng.lists.nbr_start[s.n_own]
    assert 0 < eng.lists.k_near < len(eng.lists.hist)


@pytest.mark.parametrize("mu", [0.0, 0.5])
def test_near_lists_change_no_bit_of_a_pour(mu):
    """A pour landing for 60 000 steps: near lists as long as the lists (nothing left
    out), and a near skin of 0.01 d filtered again every few dozen steps (and rebuilt at
    other steps), on one chunk and on three, give one digest."""
    x, L = _pour()
    runs = []
    for near_skin, nchunk in ((0.2, 1), (0.01, 1), (0.01, 3)):
        eng = make_engine(x, L=L, mu=mu, gravity=1.0, gamma_t=10.0 if mu else 0.0, near_skin=near_skin)
        eng.set_chunks(nchunk)
        eng.phys = dataclasses.replace(eng.phys, floor=True)
        eng.advance(60000)
        assert eng.contacts() > len(x) // 2
        lists = eng.lists
        runs.append((digest(gather_state(eng.state)), lists.n_filters - eng.n_rebuilds, lists.k_near, len(lists.hist),
                     eng.n_rebuilds))
    assert len({r[0] for r in runs}) == 1
    whole, small = runs[0], runs[1]
    # nothing left out with the whole reach; the small reach filtered between rebuilds and kept fewer
    assert whole[2] == whole[3]
    assert small[1] > 20 and small[2] < 0.8 * small[3]
    # the small reach's bound of the displacement since the build rebuilt at other steps: no bit changed
    assert small[4] != whole[4]
