"""Migration, halo and refresh of ``Domain`` on buffers, without the engine.

A column of particles spaced 0.5 d in z over K ranks: slabs are several halo
widths thick, so each rank talks only to the next ones; rows moved, slots
carried, ghosts exact copies after a refresh.
"""
import numpy as np
import pytest

from mpdem.decomp import Domain, merge_sorted
from mpdem.state import FIELDS, MOVE_FIELDS, ROW, SLOT

N = 160


def column():
    """The whole set every rank starts from: ids 1000.., z = 0.25 + 0.5 k [d]."""
    k = np.arange(N)
    x = np.column_stack([(0.37 * k) % 5.0, (0.61 * k) % 5.0, 0.25 + 0.5 * k])
    rng = np.random.default_rng(2)
    return {"id": 1000 + k, "x": x, "v": rng.normal(size=(N, 3)), "omega": rng.normal(size=(N, 3)),
            "fixed": (k < 5).astype(np.uint8)}


def gather_owned(comm, st):
    """{id: (x, v, omega, slot ids, slot Delta s)} of every owned particle of every rank."""
    own = {}
    for part in comm.allgather([(int(st.id[i]), st.x[i].copy(), st.v[i].copy(), st.omega[i].copy(),
                                 *(a.copy() for a in st.slots_of(i))) for i in range(st.n_own)]):
        for i, *rest in part:
            assert i not in own, f"particle {i} owned twice"
            own[i] = rest
    return own


def check_ghosts(comm, dom, st, members=True):
    """Ghost rows are exact copies of their owners' x, v, omega; with ``members``,
    they are exactly the particles within r_list of this slab (true right after a rebuild)."""
    own = gather_owned(comm, st)
    if members:
        b, r = dom.bounds, comm.Get_rank()
        want = {i for i, (x, *_) in own.items() if b[r] - dom.r_list <= x[2] < b[r + 1] + dom.r_list}
        want -= set(st.id[:st.n_own].tolist())
        assert sorted(st.id[st.n_own:st.n_rows].tolist()) == sorted(want)
    for k in range(st.n_own, st.n_rows):
        x, v, w = own[int(st.id[k])][:3]
        assert st.x[k].tobytes() == x.tobytes() and st.v[k].tobytes() == v.tobytes()
        assert st.omega[k].tobytes() == w.tobytes()
    return own


def test_halo_talks_to_slabs_in_reach_and_refresh_copies_exactly(comm):
    dom = Domain(comm, r_list=1.2)
    st = dom.scatter(column(), 5.0, 5.0)
    dom.rebuild(st)
    check_ghosts(comm, dom, st)
    P, r = comm.Get_size(), comm.Get_rank()
    to, frm = dom.reach()
    assert set(to.tolist()) == set(frm.tolist()) == {q for q in (r - 1, r + 1) if 0 <= q < P}
    if P > 1:
        assert dom._plan.peers == 2 * len(to)
    ghosts = st.id[st.n_own:st.n_rows].copy()
    # owners change x, v, omega in place (ghost rows untouched): a refresh brings the ghosts along
    for step in range(3):
        n = st.n_own
        st.x[:n] += 1e-3 * (step + 1) * np.sin(st.id[:n, None] * [1.0, 2.0, 3.0])
        st.v[:n] *= -1.5
        st.omega[:n, 2] = np.nextafter(st.omega[:n, 2], np.inf)
        t = dom.comm_seconds
        dom.refresh(st)
        assert dom.comm_seconds > t or P == 1
        assert np.array_equal(st.id[st.n_own:st.n_rows], ghosts)
        check_ghosts(comm, dom, st, members=False)


def test_a_refresh_packed_by_the_plans_layout_is_the_plans_own(comm):
    """``GhostPlan.layout`` names every sent and received row's place in the flat buffers: rows packed
    there by hand (as the GPU's ``pack_ghosts`` packs them), exchanged (``exchange``) and unpacked by hand
    give the ghosts ``run`` gives."""
    dom = Domain(comm, r_list=1.2)
    st = dom.scatter(column(), 5.0, 5.0)
    dom.rebuild(st)
    if comm.Get_size() == 1:
        # one rank has no ghosts and no plan
        with pytest.raises(RuntimeError, match="before the first rebuild"):
            dom.plan
        return
    n, m = st.n_own, st.n_rows
    st.x[:n] += 1e-3 * np.cos(st.id[:n, None] * [1.0, 2.0, 3.0])
    st.v[:n] *= -2.0
    dom.refresh(st)
    want = [a[n:m].copy() for a in (st.x, st.v, st.omega)]
    plan = dom.plan
    sr, sa, ss, rr, ra, rs = plan.layout()
    assert len(sr) == sum(len(rows) for rows, _ in plan.sends) and list(rr) == list(range(n, m))
    for a in (st.x, st.v, st.omega):
        a[n:m] = np.nan
    for f, a in enumerate((st.x, st.v, st.omega)):
        for k in range(3):
            plan.send_buf[sa + f * ss + k] = a[sr, k]
    t = dom.comm_seconds
    plan.exchange()
    assert dom.comm_seconds > t
    for f, a in enumerate((st.x, st.v, st.omega)):
        for k in range(3):
            a[rr, k] = plan.recv_buf[ra + f * rs + k]
    for got, w in zip((st.x, st.v, st.omega), want):
        assert np.array_equal(got[n:m], w)


def test_migration_moves_rows_with_their_slots(comm):
    dom = Domain(comm, r_list=1.2)
    st = dom.scatter(column(), 5.0, 5.0)
    n = st.n_own
    # slots: each particle in contact with the next two ids, Delta s from the id (with a -0.0)
    partner = np.repeat(st.id[:n], 2) + np.tile([1, 2], n)
    ds = np.column_stack([partner * 1e-3, -partner * 1e-4, np.full(2 * n, -0.0)])
    st.set_contacts(np.full(n, 2), partner, ds)
    dom.rebuild(st)
    before = gather_owned(comm, st)
    # everything moves up by 25 d: many particles change rank, on 4 ranks some by two slabs
    # (the bounds then move too: the top rank holds more than its share)
    st.x[:st.n_own, 2] += 25.0
    dom.rebuild(st)
    after = check_ghosts(comm, dom, st)
    assert set(after) == set(before) and len(after) == N
    b, r = dom.bounds, comm.Get_rank()
    assert np.all((st.x[:st.n_own, 2] >= b[r]) & (st.x[:st.n_own, 2] < b[r + 1]))
    for i, (x, v, w, sid, sds) in after.items():
        x0, v0, w0, sid0, sds0 = before[i]
        assert x.tobytes() == (x0 + [0.0, 0.0, 25.0]).tobytes() and v.tobytes() == v0.tobytes()
        assert sid.tolist() == [i + 1, i + 2] and sid.tobytes() == sid0.tobytes()
        assert sds.tobytes() == sds0.tobytes()
    moved = int(dom.sum_int(np.array([dom.n_migrated]))[0])
    assert moved > 0 or comm.Get_size() == 1


def test_migration_carries_every_migrating_field(comm):
    """Every field the registry says migrates (forces, torques, wall histories, slots, ...) arrives bit for bit."""
    dom = Domain(comm, r_list=1.2)
    st = dom.scatter(column(), 5.0, 5.0)
    n = st.n_own
    rng = np.random.default_rng([7, comm.Get_rank()])
    for f in ROW:
        if f.dtype == np.float64 and f.name != "x":
            getattr(st, f.name)[:n] = rng.normal(size=(n,) + f.shape)
    counts = rng.integers(0, 4, n)
    m = int(counts.sum())
    st.set_contacts(counts, **{f.name: (rng.integers(0, N, (m,) + f.shape) if f.dtype == np.int64
                                        else rng.normal(size=(m,) + f.shape)) for f in SLOT})
    dom.rebuild(st)
    moving = [f for f in FIELDS if f.migrates]
    st.x[:st.n_own, 2] += 25.0
    before = merge_sorted(comm.allgather(st.select(st.id_order(), moving)))
    dom.rebuild(st)
    after = merge_sorted(comm.allgather(st.select(st.id_order(), moving)))
    assert set(after) == set(before) == set(MOVE_FIELDS)
    for k in MOVE_FIELDS:
        assert after[k].dtype == before[k].dtype and after[k].tobytes() == before[k].tobytes(), k
    assert int(dom.sum_int(np.array([dom.n_migrated]))[0]) > 0 or comm.Get_size() == 1


def test_work_balance_splits_the_measured_seconds(comm):
    """Rank 0 reports twice the seconds of every other rank for the same number of particles:
    with ``by_work`` and no damping, its slab shrinks until its particles, each carrying its
    old rank's seconds over its particles, hold 1/P of the whole; the counts stay balanced while
    a rank has measured nothing; every particle is still owned once."""
    P, r = comm.Get_size(), comm.Get_rank()
    whole = column()
    mobile = int((whole["fixed"] == 0).sum())
    dom = Domain(comm, r_list=1.2, tolerance=0.05, damping=1.0, by_work=True)
    st = dom.scatter(whole, 5.0, 5.0)
    counts = comm.allgather(int((st.fixed[:st.n_own] == 0).sum()))
    # no rank measured anything yet: the counts decide, and they are balanced
    dom.rebuild(st, 0.0)
    assert dom.n_rebalances == 0
    dom.rebuild(st, 2.0 if r == 0 else 1.0)
    after = comm.allgather(int((st.fixed[:st.n_own] == 0).sum()))
    assert sum(after) == mobile
    if P == 1:
        assert dom.n_rebalances == 0
        return
    assert dom.n_rebalances == 1
    # rank 0's particles cost 2 / n0 each, the others' 1 / n_r: rank 0 keeps the k with 2 k / n0 = (P + 1) / P
    want = counts[0] * (P + 1) / (2 * P)
    assert abs(after[0] - want) <= 1.0
    assert after[0] < counts[0]
    assert len(gather_owned(comm, st)) == N


def test_bounds_from_height_histograms_are_the_exact_quantiles_within_a_bin(comm):
    """``histogram_bounds`` (each rank's heights counted in bins, the counts summed or gathered: no rank
    sees another's heights) puts each bound within a bin of the exact quantile that ``balanced_bounds``
    takes from every height, by count and by each rank's work; every rank gets the same bounds."""
    from mpdem.decomp import HIST_BINS
    P, r = comm.Get_size(), comm.Get_rank()
    g = np.random.default_rng(7)
    z_all = np.concatenate([g.uniform(0.5, 30.0, 3000), g.normal(12.0, 2.0, 2000)])
    owner = g.integers(0, P, len(z_all))
    works = np.array([1.0 + q for q in range(P)])
    mine = z_all[owner == r]
    dom = Domain(comm, r_list=1.2)
    width = (z_all.max() - z_all.min()) / HIST_BINS
    by_count = dom.histogram_bounds(mine)
    cost = np.array([works[q] / (owner == q).sum() for q in owner])
    by_work = dom.histogram_bounds(mine, works)
    for got, want in ((by_count, dom.balanced_bounds(z_all)), (by_work, dom.balanced_bounds(z_all, cost))):
        assert got.shape == (P - 1,) and np.all(np.diff(got) >= 0)
        assert np.all(np.abs(got - want) <= 1.5 * width), (got, want)
        assert all(np.array_equal(got, other) for other in comm.allgather(got))
    # the counts below each bound: r / P of all, but for the heights in the bound's bin
    for q, b in enumerate(by_count, start=1):
        in_bin = int(np.sum(np.abs(z_all - b) <= width))
        assert abs(int((z_all < b).sum()) - q * len(z_all) / P) <= in_bin + 1
