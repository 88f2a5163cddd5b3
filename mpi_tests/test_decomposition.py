"""The slab decomposition gives the one-rank result bit for bit (ARCHITECTURE.md, "Invariants").

Run under ``mpiexec -n K python -m pytest mpi_tests`` for K = 2, 3, 4: each
test runs the same pile on COMM_WORLD and, on rank 0, on COMM_SELF (one
rank), and compares digests of the state sorted by id.
"""
import os
import tempfile

import numpy as np
import pytest

from mpdem import config
from mpdem.io import tables
from mpdem.driver.simulation import Run

from mpi_helpers import PILE, reference_key, run, serial_digest, shared_dir


def test_pour_and_landing_match_one_rank(comm):
    """Free fall, landing, migrations and rebalances: the digest of one rank. The slabs balance
    counts here, which rebalance in every pour whatever the timing (the work: below)."""
    cfg = config.load(None, PILE + ["run.max_steps=40000", "decomp.balance_by=count"])
    base = shared_dir(comm)
    r, s = run(cfg, os.path.join(base, "par"), comm)
    ref = serial_digest(cfg, os.path.join(base, "ser"), comm)
    migrated = int(r.domain.sum_int(np.array([r.domain.n_migrated]))[0])
    assert migrated > 20
    assert r.domain.n_rebalances >= 1
    if comm.Get_rank() == 0:
        assert s["digest"] == ref
        assert s["migrated"] == migrated


def test_particles_and_contacts_are_conserved(comm):
    cfg = config.load(None, PILE + ["run.max_steps=30000"])
    base = shared_dir(comm)
    r, s = run(cfg, os.path.join(base, "c"), comm)
    st = r.state
    n_total = int(r.domain.sum_int(np.array([st.n_own]))[0])
    assert n_total == r.n_mobile + r.n_bed
    ids = np.concatenate(comm.allgather(st.id[:st.n_own].copy()))
    assert len(np.unique(ids)) == len(ids) == n_total
    # every contact slot has its mirror on the partner's owner, exactly negated
    slots = {}
    for part in comm.allgather([(int(st.id[i]), int(jid), ds.copy())
                                for i in range(st.n_own) for jid, ds in zip(*st.slots_of(i))]):
        for a, b, ds in part:
            slots[(a, b)] = ds
    fixed_ids = set(np.concatenate(comm.allgather(st.id[:st.n_own][st.fixed[:st.n_own] == 1])).tolist())
    assert len(slots) > 0
    for (a, b), ds in slots.items():
        if b in fixed_ids:
            continue
        assert np.array_equal(slots[(b, a)], -ds)


def test_ghosts_equal_a_brute_force_search(comm):
    cfg = config.load(None, PILE + ["run.max_steps=5000"])
    base = shared_dir(comm)
    r = Run.new(cfg, os.path.join(base, "g"), comm, quiet=True)
    r.run()
    r.engine.rebuild()
    st, dom = r.state, r.domain
    everything = comm.allgather((st.id[:st.n_own].copy(), st.x[:st.n_own].copy()))
    all_ids = np.concatenate([e[0] for e in everything])
    all_x = np.concatenate([e[1] for e in everything])
    lo = dom.bounds[comm.Get_rank()] - dom.r_list
    hi = dom.bounds[comm.Get_rank() + 1] + dom.r_list
    mine = set(st.id[:st.n_own].tolist())
    want = {int(i) for i, z in zip(all_ids, all_x[:, 2]) if lo <= z < hi and int(i) not in mine}
    ghosts = st.id[st.n_own:st.n_rows]
    assert set(ghosts.tolist()) == want and len(ghosts) == len(want)
    # ghost coordinates are exact copies of the owners'
    where = {int(i): k for k, i in enumerate(all_ids)}
    for k in range(st.n_own, st.n_rows):
        assert np.array_equal(st.x[k], all_x[where[int(st.id[k])]])


def test_pile_too_small_for_the_ranks(comm):
    """Fewer particles than ranks: most ranks own nothing and still take part."""
    base = shared_dir(comm)
    p = os.path.join(base, "tiny.txt")
    if comm.Get_rank() == 0:
        tables.write_table(p, np.array([4, 9, 1]),
                          np.array([[1.0, 1.0, 1.0], [1.3, 1.1, 2.2], [3.5, 3.5, 1.0]]),
                          np.array([[0.0, 0.0, 0.0], [0.1, 0.0, -1.0], [0.0, 0.0, 0.0]]),
                          np.array([1, 0, 1], np.uint8))
    comm.Barrier()
    cfg = config.load(None, ["run.max_steps=8000", "box.L_x=5.0", "box.L_y=5.0", f'run.initial_file="{p}"',
                             "output.progress_every=100000", "contact.mu=0.5"])
    r, s = run(cfg, os.path.join(base, "tp"), comm)
    owners = comm.allgather(r.state.n_own)
    assert sum(owners) == 3
    if comm.Get_size() > 3:
        assert 0 in owners
    ref = serial_digest(cfg, os.path.join(base, "ts"), comm)
    if comm.Get_rank() == 0:
        assert s["digest"] == ref


def write_stack(path, layers=8, n=5, L=6.0, gap=0.001, jitter=0.0002, seed=3):
    """A loose body-centred stack of n x n layers on an n x n bed in an L x L box.

    Each sphere sits over a hollow of the layer below, ``gap`` [d] above
    contact, shifted by up to ``jitter`` [d] in x and y; it closes under
    gravity in a few hundred steps. Ids: mobile spheres first, then the bed.
    """
    a = L / n
    grid = np.stack(np.meshgrid(np.arange(n), np.arange(n), indexing="ij"), -1).reshape(-1, 2) * a
    h = np.sqrt(1.0 - a * a / 2) + gap
    mob = np.concatenate([np.column_stack([(grid + a / 2 * (k % 2 == 0)) % L, np.full(n * n, 0.5 + (k + 1) * h)])
                          for k in range(layers)])
    mob[:, :2] = (mob[:, :2] + jitter * np.random.default_rng(seed).uniform(-1, 1, (len(mob), 2))) % L
    x = np.concatenate([mob, np.column_stack([grid, np.full(n * n, 0.5)])])
    fixed = np.r_[np.zeros(len(mob), np.uint8), np.ones(n * n, np.uint8)]
    tables.write_table(path, np.arange(len(x)), x, np.zeros_like(x), fixed)


def stack_config(comm, base, mu):
    """Config of 1500 steps of the ``write_stack`` stack (written by rank 0 in ``base``), gamma_t = 25.7."""
    p = os.path.join(base, "stack.txt")
    if comm.Get_rank() == 0:
        write_stack(p)
    comm.Barrier()
    return config.load(None, ["run.max_steps=1500", "box.L_x=6.0", "box.L_y=6.0", f'run.initial_file="{p}"',
                              "output.progress_every=100000", f"contact.mu={mu}", "contact.gamma_t=25.7"])


@pytest.mark.parametrize("mu", [0.0, 0.5])
def test_frictionless_pile_matches_one_rank(comm, mu):
    """mu = 0 with gamma_t > 0: the stored Delta s are exact zeros (or, if
    docs/model.md 2.4 is run with mu = 0, -m_eff gamma_t v_t / k_t); a zero must
    be +0.0 whichever partner computed the pair, else its sign, hence the
    digest, depends on the ranks. mu = 0.5 is the control: the same stack
    with friction."""
    base = shared_dir(comm)
    cfg = stack_config(comm, base, mu)
    r, s = run(cfg, os.path.join(base, "fp"), comm)
    n_contacts = r.engine.contacts()
    ref = serial_digest(cfg, os.path.join(base, "fs"), comm)
    assert n_contacts > 2 * r.n_mobile        # the stack has closed: contacts all the way up
    if comm.Get_rank() == 0:
        assert s["digest"] == ref


def test_ranks_times_threads_match_one_rank_one_thread(comm):
    """2 ranks x 2 threads (rows split into chunks, pairs computed once within a
    chunk) give the digest of one rank with one thread: a frictional stack with
    tangential damping, closed into contacts all the way up. On 3 and 4 ranks
    only rank 0 has 2 threads (a mixed split; all would oversubscribe the 2
    cores of CI, where every parallel loop waits for a time slice)."""
    from mpdem import threads
    base = shared_dir(comm)
    cfg = stack_config(comm, base, 0.5)
    t = 2 if comm.Get_size() == 2 or comm.Get_rank() == 0 else 1
    threads.configure(t)
    try:
        r, s = run(cfg, os.path.join(base, "tp"), comm)
        assert r.engine.nchunk == t          # one chunk per thread
        n_contacts = r.engine.contacts()
    finally:
        threads.configure(1)
    ref = serial_digest(cfg, os.path.join(base, "ts"), comm)
    assert n_contacts > 2 * r.n_mobile
    if comm.Get_rank() == 0:
        assert s["digest"] == ref


def test_a_rank_that_owns_nothing(comm):
    """Bounds pushed so that rank 0 owns nothing for a while: same digest."""
    cfg = config.load(None, PILE + ["run.max_steps=3000", "decomp.balance_tolerance=100.0"])
    base = shared_dir(comm)
    r = Run.new(cfg, os.path.join(base, "e"), comm, quiet=True)
    if comm.Get_size() > 1:
        # move everything away from rank 0's slab; migration at the first rebuild follows
        r.domain.bounds[1] = -1e9
        r.domain.bounds[1:-1] = np.maximum.accumulate(r.domain.bounds[1:-1])
    r.run()
    owned0 = comm.bcast(r.state.n_own, root=0)
    s = r.finish()
    ref = serial_digest(cfg, os.path.join(base, "es"), comm)
    if comm.Get_size() > 1:
        assert owned0 == 0
    if comm.Get_rank() == 0:
        assert s["digest"] == ref


def write_sparse_bed_pile(path):
    """Six bed spheres on a 5 d x 5 d box (far too few to hold a pile) under 96 mobile
    spheres on a lattice from z = 2 up, with small random velocities: most fall to the wall."""
    rng = np.random.default_rng(11)
    g = np.array([0.5, 1.75, 3.0, 4.25])
    mob = np.array([[x, y, 2.0 + 1.25 * k] for k in range(6) for y in g for x in g])
    bed = np.array([[0.5, 0.5, 0.5], [2.5, 1.0, 0.5], [4.0, 3.0, 0.5], [1.0, 4.0, 0.5], [3.0, 3.5, 0.5],
                    [2.0, 2.5, 0.5]])
    x = np.concatenate([mob, bed])
    v = np.concatenate([rng.normal(scale=0.3, size=mob.shape), np.zeros(bed.shape)])
    fixed = np.r_[np.zeros(len(mob)), np.ones(len(bed))].astype(np.uint8)
    tables.write_table(path, np.arange(1, len(x) + 1), x, v, fixed)


@pytest.mark.parametrize("mu", [0.0, 0.5])
def test_a_pile_on_the_wall_under_a_sparse_bed_matches_one_rank(comm, mu):
    """bed.wall: spheres fall through the bed onto the wall plane (below z = 0.9, under the bed
    spheres' tops) and bounce or rest there with their own wall histories; migrations carry
    them, and the digest is the one-rank digest."""
    base = shared_dir(comm)
    p = os.path.join(base, "sparse.txt")
    if comm.Get_rank() == 0:
        write_sparse_bed_pile(p)
    comm.Barrier()
    cfg = config.load(None, ["run.max_steps=40000", "box.L_x=5.0", "box.L_y=5.0", f'run.initial_file="{p}"',
                             "output.progress_every=100000", f"contact.mu={mu}", "bed.wall=true"])
    r, s = run(cfg, os.path.join(base, "wp"), comm)
    st = r.state
    on_wall = int(r.domain.sum_int(np.array([np.count_nonzero(
        (st.x[:st.n_own, 2] < 0.9) & (st.fixed[:st.n_own] == 0))]))[0])
    ref = serial_digest(cfg, os.path.join(base, "ws"), comm)
    assert on_wall >= 8
    if comm.Get_rank() == 0:
        assert s["digest"] == ref


def test_a_reference_is_known_by_its_inputs_not_their_paths():
    """serial_digest computes each one-rank reference once per session, keyed by reference_key:
    the same bytes under another path are the same run; one byte or one config value more is another."""
    d = tempfile.mkdtemp()          # this rank's own: no collective call
    paths = [os.path.join(d, name) for name in ("a.txt", "b.txt", "c.txt")]
    for p in paths[:2]:
        write_stack(p)
    write_stack(paths[2], gap=0.002)

    def key(p, *sets):
        return reference_key(config.load(None, ["run.max_steps=10", "box.L_x=6.0", "box.L_y=6.0",
                                                 f'run.initial_file="{p}"', *sets]))

    assert key(paths[0]) == key(paths[1])
    assert key(paths[0]) != key(paths[2])
    assert key(paths[0]) != key(paths[1], "contact.mu=0.25")
    pile = [*PILE, "run.max_steps=10"]
    assert reference_key(config.load(None, pile)) != reference_key(config.load(None, pile + ["run.max_steps=7"]))


def test_slabs_balanced_by_work_match_one_rank(comm, monkeypatch):
    """Bounds moved by the measured work (``decomp.balance_by = work``), with rank 0's seconds
    made three times what it measured so that they do move at every rebuild, and at the checks
    between rebuilds (``decomp.balance_every``; ``decomp.balance_seconds``, the seconds' floor, lifted),
    whose rebuilds come when no particle's motion asks for one: the digest of one rank."""
    from mpdem.engine.base import EngineBase
    cfg = config.load(None, PILE + ["run.max_steps=20000", "decomp.balance_by=work", "decomp.balance_tolerance=0.02",
                                    "decomp.balance_every=100", "decomp.balance_seconds=0"])
    base = shared_dir(comm)
    if comm.Get_size() > 1 and comm.Get_rank() == 0:
        work = EngineBase.work_since_rebuild
        monkeypatch.setattr(EngineBase, "work_since_rebuild", lambda self: 3.0 * work(self))
    r, s = run(cfg, os.path.join(base, "w"), comm)
    monkeypatch.undo()
    ref = serial_digest(cfg, os.path.join(base, "ws"), comm)
    if comm.Get_size() > 1:
        assert r.domain.by_work
        assert r.domain.n_rebalances >= 3
        # every rank answered the checks alike (their rebuilds are collectives: one rank alone would hang)
        assert r.domain.n_balance_rebuilds >= 1
        assert len(set(comm.allgather(r.domain.n_balance_rebuilds))) == 1
    if comm.Get_rank() == 0:
        assert s["digest"] == ref
