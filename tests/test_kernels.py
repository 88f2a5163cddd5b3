"""Neighbour lists against brute force; exact sums; integration details."""
import math
import random

import numpy as np
import pytest

from mpdem.kernels.bundles import Lists, Particles, Slots, make_box
from mpdem.kernels.chunks import chunk_bounds, chunk_of
from mpdem.kernels.exactsum import add_exact, new_accumulator, to_float
from mpdem.kernels.neighbours import build_neighbours
from mpdem.kernels.particle import INERTIA


def brute_pairs(x, L_x, L_y, rc):
    d = x[:, None, :] - x[None, :, :]
    d[..., 0] -= L_x * np.round(d[..., 0] / L_x)
    d[..., 1] -= L_y * np.round(d[..., 1] / L_y)
    r2 = np.einsum("ijk,ijk->ij", d, d)
    np.fill_diagonal(r2, np.inf)
    return r2 < rc * rc


@pytest.mark.parametrize("L_x,L_y,zspan", [(10.0, 10.0, 8.0), (3.0, 2.5, 5.0), (3.7, 3.7, 5.0), (7.3, 4.1, 2000.0)])
def test_neighbour_lists_match_brute_force(L_x, L_y, zspan):
    g = np.random.default_rng(5)
    n = 600
    x = np.column_stack([g.random(n) * L_x, g.random(n) * L_y, g.random(n) ** 4 * zspan])
    fixed = (g.random(n) < 0.2).astype(np.uint8)
    ids = g.permutation(n).astype(np.int64) * 3 + 11
    rc = 1.2
    start = np.zeros(n + 1, np.int64)
    lst = np.zeros(10, np.int32)
    box = make_box(L_x, L_y)
    # short of room, the build asks for more (each chunk's share must hold its rows' lists)
    need = build_neighbours(x, n, n, fixed, ids, box, rc, start, lst, 3)
    assert need > len(lst)
    lst = np.zeros(need, np.int32)
    total = build_neighbours(x, n, n, fixed, ids, box, rc, start, lst, 3)
    assert total <= need and start[n] == total
    ref = brute_pairs(x, L_x, L_y, rc)
    for i in range(n):
        got = lst[start[i]:start[i + 1]]
        if fixed[i]:
            assert len(got) == 0
            continue
        assert sorted(got.tolist()) == sorted(np.flatnonzero(ref[i]).tolist())
        assert np.all(np.diff(ids[got]) > 0)
    # other chunk counts: the same lists; one chunk needs room for exactly the entries
    for nchunk in (1, 2, 5, 700):
        s_start = np.zeros(n + 1, np.int64)
        short = np.zeros(total - 1, np.int32)
        need = build_neighbours(x, n, n, fixed, ids, box, rc, s_start, short, nchunk)
        assert need > len(short) and (nchunk > 1 or need == total)
        s_lst = np.zeros(need, np.int32)
        assert build_neighbours(x, n, n, fixed, ids, box, rc, s_start, s_lst, nchunk) == total
        assert np.array_equal(s_start, start) and np.array_equal(s_lst[:total], lst[:total])


def test_exact_sum_is_order_independent_and_correctly_rounded():
    from fractions import Fraction
    r = random.Random(1)
    vals = [r.uniform(0, 1) * 10 ** r.randint(-300, 300) for _ in range(2000)]
    vals += [5e-324, 1e-310, 1.7e308 / 4096, 0.0, -3.5, 2.5]
    exact = sum(Fraction(v) for v in vals)
    acc = new_accumulator()
    for v in vals:
        add_exact(acc, v)
    assert to_float(acc) == float(exact)
    # split over "ranks" in another order: same limbs, same bits
    r.shuffle(vals)
    parts = [new_accumulator() for _ in range(3)]
    for k, v in enumerate(vals):
        add_exact(parts[k % 3], v)
    total = parts[0] + parts[1] + parts[2]
    assert to_float(total) == float(exact)
    assert math.fsum(vals) == float(exact)


def test_select_contacts_takes_the_right_segments():
    from mpdem.state import select_contacts
    counts = np.array([2, 0, 3, 1, 0])
    partner = np.array([10, 11, 20, 21, 22, 30])
    ds = np.arange(18.0).reshape(6, 3)
    c, p, d = select_contacts(counts, partner, ds, [3, 0, 1, 2])
    assert c.tolist() == [1, 2, 0, 3]
    assert p.tolist() == [30, 10, 11, 20, 21, 22]
    assert np.array_equal(d, ds[[5, 0, 1, 2, 3, 4]])
    c, p, d = select_contacts(counts, partner, ds, [])
    assert len(c) == len(p) == len(d) == 0


# ---- kernel round trips (issue 24): a fault says which kernel it is in ----------------------

def _lists(n=300, L=5.0, nchunk=3, seed=9):
    """A random set of rows (all owned, a fifth of them bed) with their lists and links."""
    from mpdem.kernels.neighbours import link_entries
    g = np.random.default_rng(seed)
    x = np.column_stack([g.random(n) * L, g.random(n) * L, g.random(n) * 6.0])
    fixed = (g.random(n) < 0.2).astype(np.uint8)
    ids = g.permutation(n).astype(np.int64) * 2 + 5
    start = np.zeros(n + 1, np.int64)
    box = make_box(L, L)
    lst = np.zeros(build_neighbours(x, n, n, fixed, ids, box, 1.2, start, np.zeros(1, np.int32), nchunk), np.int32)
    build_neighbours(x, n, n, fixed, ids, box, 1.2, start, lst, nchunk)
    link = np.zeros(len(lst), np.int32)
    comp_start = np.zeros(n + 1, np.int64)
    lists = Lists(start, lst, link, comp_start)
    k = int(link_entries(n, fixed, lists, nchunk))
    return dict(n=n, x=x, fixed=fixed, ids=ids, start=start, lst=lst, link=link, comp_start=comp_start,
                k=k, nchunk=nchunk, lists=lists)


@pytest.mark.parametrize("nchunk", [1, 3, 7])
def test_link_entries_give_each_pair_one_computing_row_in_a_chunk(nchunk):
    t = _lists(nchunk=nchunk)
    n, start, lst, link = t["n"], t["start"], t["lst"], t["link"]
    chunk = np.zeros(n, np.int64)
    for c in range(nchunk):
        lo, hi = chunk_bounds(c, n, nchunk)
        chunk[lo:hi] = c
    entry = {(i, int(j)): int(link[e]) for i in range(n) for e, j in zip(range(start[i], start[i + 1]),
                                                                        lst[start[i]:start[i + 1]])}
    computed = [v for v in entry.values() if v >= 0]
    assert sorted(computed) == list(range(t["k"]))                 # each slot computed exactly once
    assert len(computed) < len(entry)                               # and some entries take theirs
    for (i, j), v in entry.items():
        if (j, i) in entry and chunk[i] == chunk[j]:
            # two mobile rows of one chunk: the lower row computes, the other takes the same slot
            lo, hi = (i, j) if i < j else (j, i)
            assert entry[(lo, hi)] >= 0 and entry[(hi, lo)] == ~entry[(lo, hi)]
        else:
            assert v >= 0                                           # bed partner or other chunk: its own
    for i in range(n):
        # a row's computed entries are its slots, in the order of its list
        mine = [int(link[e]) for e in range(start[i], start[i + 1]) if link[e] >= 0]
        assert mine == list(range(t["comp_start"][i], t["comp_start"][i + 1]))


def test_history_slots_round_trip_through_the_list_entries():
    from mpdem.kernels import history
    t = _lists(nchunk=4)
    n, k, epoch = t["n"], t["k"], 41
    g = np.random.default_rng(3)
    hist = g.standard_normal((k, 3))
    stamp = np.where(g.random(k) < 0.6, history.stamp_of(epoch), history.stamp_of(epoch - 1)).astype(np.uint32)
    slot_n = np.zeros(n, np.int32)
    total = history.count_contacts(n, t["lists"], Slots(hist, stamp, np.zeros((0, 6))), epoch, slot_n, 4)
    slot_start = np.zeros(n + 1, np.int64)
    np.cumsum(slot_n, out=slot_start[1:])
    slot_id, slot_ds = np.empty(total, np.int64), np.empty((total, 3))
    history.entries_to_slots(n, t["ids"], t["lists"], Slots(hist, stamp, np.zeros((0, 6))), epoch, slot_start,
                             slot_id, slot_ds, 4)
    # each row's slots: its partners in contact, by id, with Delta s from its own side
    for i in range(n):
        want = [(int(t["ids"][j]), (hist[lk] if lk >= 0 else -hist[~lk]).tolist())
                for e, j in zip(range(t["start"][i], t["start"][i + 1]), t["lst"][t["start"][i]:t["start"][i + 1]])
                for lk in [int(t["link"][e])] if stamp[lk if lk >= 0 else ~lk] == history.stamp_of(epoch)]
        got = [(int(a), b.tolist()) for a, b in zip(slot_id[slot_start[i]:slot_start[i + 1]],
                                                    slot_ds[slot_start[i]:slot_start[i + 1]])]
        assert got == want
    # and back: the slots in contact get their history and the stamp, the others zero and the one before
    hist2, stamp2 = np.full((k, 3), 7.0), np.zeros(k, np.uint32)
    history.slots_to_entries(n, t["ids"], t["lists"], slot_start, slot_id, slot_ds,
                             Slots(hist2, stamp2, np.zeros((0, 6))), epoch, 4)
    on = stamp == history.stamp_of(epoch)
    assert np.array_equal(stamp2, stamp) and np.array_equal(hist2[on], hist[on]) and np.all(hist2[~on] == 0.0)


def test_kick_drift_is_a_half_kick_a_drift_and_a_wrap():
    from mpdem.kernels.integrate import kick_drift
    g = np.random.default_rng(4)
    n, L, dt = 400, 6.0, 1e-3
    x = np.column_stack([g.random(n) * L, g.random(n) * L, 1 + g.random(n) * 5])
    x[0, 0], x[1, 1] = L - 1e-9, 1e-9                           # two that leave the box this step
    v, omega = g.standard_normal((n, 3)), g.standard_normal((n, 3))
    v[0, 0], v[1, 1] = 1.0, -1.0
    f, torque = g.standard_normal((n, 3)), g.standard_normal((n, 3))
    fixed = (g.random(n) < 0.1).astype(np.uint8)
    fixed[:2] = 0
    x_ref = x - 0.01 * g.standard_normal((n, 3))
    want = {k: a.copy() for k, a in dict(x=x, v=v, omega=omega).items()}
    mob = fixed == 0
    want["v"][mob] += 0.5 * dt * f[mob]
    want["omega"][mob] += 0.5 * dt * torque[mob] / INERTIA
    want["x"][mob] += dt * want["v"][mob]
    want["x"][:, :2] %= L
    d = want["x"][mob] - x_ref[mob]
    d[:, :2] -= L * np.round(d[:, :2] / L)
    for nchunk in (1, 5):
        xs, vs, ws = x.copy(), v.copy(), omega.copy()
        d2, zlo, zhi = kick_drift(n, Particles(xs, vs, ws, f, torque, fixed), x_ref, dt, make_box(L, L),
                                  np.zeros((nchunk, 3)), False)
        assert np.allclose(xs, want["x"], rtol=0, atol=1e-12) and np.array_equal(vs, want["v"])
        assert np.allclose(ws, want["omega"], rtol=1e-15) and np.array_equal(xs[~mob], x[~mob])
        assert 0 <= xs[0, 0] < L and 0 <= xs[1, 1] < L
        assert d2 == pytest.approx((d ** 2).sum(axis=1).max(), rel=1e-9)
        assert (zlo, zhi) == (xs[mob, 2].min(), xs[mob, 2].max())


def test_kick_drift_with_a_pending_kick_is_kick_then_kick_drift_bit_for_bit():
    """The deferred second half-kick (``pending``) in the first pass gives the bits of the
    separate ``kick`` followed by ``kick_drift``, serial and over chunks."""
    from mpdem.kernels.integrate import kick, kick_drift, kick_drift_serial, kick_serial
    g = np.random.default_rng(5)
    n, L, dt = 500, 6.0, 1e-3
    x = np.column_stack([g.random(n) * L, g.random(n) * L, 1 + g.random(n) * 5])
    v, omega = g.standard_normal((n, 3)), g.standard_normal((n, 3))
    f, torque = 1e3 * g.standard_normal((n, 3)), 1e3 * g.standard_normal((n, 3))
    fixed = (g.random(n) < 0.1).astype(np.uint8)
    x_ref = x - 0.01 * g.standard_normal((n, 3))
    box = make_box(L, L)
    for kd, kk, nchunk in ((kick_drift_serial, kick_serial, 1), (kick_drift, kick, 3)):
        want = [a.copy() for a in (x, v, omega)]
        kk(n, Particles(*want, f, torque, fixed), dt)
        r_want = kd(n, Particles(*want, f, torque, fixed), x_ref, dt, box, np.zeros((nchunk, 3)), False)
        got = [a.copy() for a in (x, v, omega)]
        r_got = kd(n, Particles(*got, f, torque, fixed), x_ref, dt, box, np.zeros((nchunk, 3)), True)
        assert r_got == r_want
        for a, b in zip(got, want):
            assert np.array_equal(a, b)
        # and the pending kick did something: without it the velocities differ
        once = [a.copy() for a in (x, v, omega)]
        kd(n, Particles(*once, f, torque, fixed), x_ref, dt, box, np.zeros((nchunk, 3)), False)
        assert not np.array_equal(once[1], want[1])


def test_particle_constants_agree_with_each_other():
    from mpdem.kernels import particle
    assert particle.INERTIA == 0.4 * particle.R ** 2                 # (2/5) m R^2, m = 1
    assert particle.INV_I == 1.0 / particle.INERTIA and particle.HALF_I == 0.5 * particle.INERTIA
    assert particle.VOLUME == pytest.approx(4 / 3 * math.pi * particle.R ** 3, rel=1e-15)
    from mpdem.build import SPHERE_VOLUME
    assert SPHERE_VOLUME == particle.VOLUME


def test_chunk_of_agrees_with_chunk_bounds():
    """Every row is in exactly the chunk whose bounds hold it, the chunks tile 0..n-1 in order
    (empty ones too, with more chunks than rows), for the thread counts and row counts of a run."""
    sizes = list(range(1, 70)) + [97, 128, 1000, 4099, 20283, 2 ** 31 - 1]
    for n in sizes:
        for nchunk in list(range(1, 40)) + [64, 100, 257]:
            edge = 0
            for c in range(nchunk):
                lo, hi = chunk_bounds(c, n, nchunk)
                assert lo == edge and lo <= hi
                edge = hi
                # the first and last rows of a chunk say so (all rows when n is small)
                rows = range(lo, hi) if n < 200 or hi - lo < 2 else (lo, lo + 1, hi - 2, hi - 1)
                assert all(chunk_of(i, n, nchunk) == c for i in rows)
            assert edge == n


def test_ghost_rows_gather_and_scatter():
    from mpdem.kernels.ghosts import gather_rows, scatter_rows
    g = np.random.default_rng(2)
    fields = tuple(g.random((20, 3)) for _ in range(3))
    rows = np.array([7, 2, 19, 0], np.intp)
    block = np.full((3, 4, 3), np.nan)
    gather_rows(fields, rows, block)
    for f in range(3):
        np.testing.assert_array_equal(block[f], fields[f][rows])
    before = tuple(a.copy() for a in fields)
    scatter_rows(fields, 15, block)
    for f in range(3):
        np.testing.assert_array_equal(fields[f][15:19], block[f])
        np.testing.assert_array_equal(fields[f][:15], before[f][:15])
        np.testing.assert_array_equal(fields[f][19:], before[f][19:])
