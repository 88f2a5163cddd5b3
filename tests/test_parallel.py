"""The communication layer on one rank: reductions, row packing, halo reach."""
import math

import numpy as np
import pytest

from mpdem import decomp
from mpdem.decomp import Domain
from mpdem.parallel import Channel
from mpdem.state import MOVE_FIELDS, State


def test_max_many_maps_nan_to_inf_into_a_reused_read_only_buffer():
    ch = Channel(None)
    a = ch.max_many(np.array([1.0, math.nan, -2.0, 0.5]))
    assert a.tolist() == [1.0, math.inf, -2.0, 0.5]
    with pytest.raises(ValueError):
        a[0] = 3.0
    b = ch.max_many([4.0, 1.0, math.nan, -1.0])
    assert b is a and a.tolist() == [4.0, 1.0, math.inf, -1.0]
    # other lengths (extra flags) get their own buffer
    assert ch.max_many([1.0, 2.0, 3.0, 4.0, 0.0, 1.0, 0.0]).tolist() == [1, 2, 3, 4, 0, 1, 0]
    assert a.tolist() == [4.0, 1.0, math.inf, -1.0]
    assert Domain(None).max(math.nan) == math.inf
    # every number passes unchanged: infinities, the largest finite, and -0.0 with its sign
    c = ch.max_many([-0.0, -math.inf, math.inf, 1.7976931348623157e308, 5e-324])
    assert c.tolist() == [0.0, -math.inf, math.inf, 1.7976931348623157e308, 5e-324]
    assert math.copysign(1.0, c[0]) == -1.0


def test_sum_int_keeps_shape_and_casts_like_before():
    ch = Channel(None)
    acc = np.arange(6, dtype=np.int64).reshape(2, 3)
    out = ch.sum_int(acc)
    assert out.dtype == np.int64 and out.shape == (2, 3) and np.array_equal(out, acc)
    assert ch.sum_int(np.array([7])).tolist() == [7]
    assert ch.sum_int([2.0]).tolist() == [2]


def _state_with_slots():
    rng = np.random.default_rng(5)
    n = 6
    st = State(np.arange(10, 10 + n), rng.uniform(0, 5, (n, 3)), rng.normal(size=(n, 3)),
               rng.normal(size=(n, 3)), np.array([0, 1, 0, 0, 1, 0], np.uint8), 5.0, 5.0)
    st.f[:n] = rng.normal(size=(n, 3))
    st.torque[:n] = rng.normal(size=(n, 3))
    st.x[2, 0] = -0.0
    counts = np.array([2, 0, 1, 3, 0, 1])
    partner = np.arange(100, 100 + counts.sum())
    ds = rng.normal(size=(counts.sum(), 3))
    ds[0, 1] = -0.0
    st.set_contacts(counts, partner, ds)
    return st


def test_packed_rows_come_back_bit_for_bit():
    st = _state_with_slots()
    part = st.take(np.array([0, 3, 4, 5]))
    floats, ints = decomp._pack(part)
    m, slots = len(part["id"]), len(part["partner"])
    fb, ib = decomp._empty_packed(m, slots)
    assert fb.shape == floats.shape and ib.shape == ints.shape
    fb[:], ib[:] = floats, ints
    got = decomp._unpack(fb, ib, m, slots)
    assert set(got) == set(MOVE_FIELDS) == set(part)
    for f in MOVE_FIELDS:
        assert got[f].dtype == np.asarray(part[f]).dtype, f
        assert np.asarray(got[f]).tobytes() == np.asarray(part[f]).astype(got[f].dtype).tobytes(), f
    other = State(np.zeros(0, np.int64), np.zeros((0, 3)), L_x=5.0, L_y=5.0)
    assert other.append([got]) == 4
    assert np.array_equal(other.count[:4], [2, 3, 0, 1])
    assert np.array_equal(other.slots_of(1)[0], part["partner"][2:5])


def _domain(bounds, rank, r_list=1.2):
    """Rank ``rank``'s view of slabs with ``bounds`` (no MPI: the decisions alone)."""
    d = Domain(None, r_list=r_list)
    d.size, d.rank = len(bounds) - 1, rank
    d._set_grid((1, 1, d.size))
    d.bounds = np.array(bounds, float)
    return d


def test_reach_covers_thin_slabs_and_skips_far_ones():
    b = [-math.inf, 0.0, 0.5, 1.0, 10.0, math.inf]   # slabs 1 and 2 thinner than the halo
    to = {r: _domain(b, r).reach()[0].tolist() for r in range(5)}
    frm = {r: _domain(b, r).reach()[1].tolist() for r in range(5)}
    assert to[0] == [1, 2, 3] and to[1] == [0, 2, 3] and to[3] == [0, 1, 2, 4] and to[4] == [3]
    for r in range(5):
        assert frm[r] == [s for s in range(5) if r in to[s]]


def test_reach_contains_every_rank_a_row_is_sent_to():
    rng = np.random.default_rng(1)
    for _ in range(200):
        inner = np.sort(rng.uniform(0, 6, 4)) if rng.random() < 0.8 else np.array([1.0, 1.0, 1.0, 4.0])
        b = np.r_[-math.inf, inner, math.inf]
        lo, hi = b[:-1] - 1.2, b[1:] + 1.2
        z = rng.uniform(-2, 8, 300)
        owner = np.searchsorted(inner, z, side="right")
        for s in range(5):
            to = set(_domain(b, s).reach()[0].tolist())
            mine = z[owner == s]
            for r in range(5):
                if r != s and np.any((mine >= lo[r]) & (mine < hi[r])):
                    assert r in to
