"""Grids of domains, columns in x and y under the slabs (``decomp.grid``), give the one-rank result bit for bit.

Run under ``mpiexec -n K python -m pytest mpi_tests`` for K = 2, 3, 4: each grid of K domains pours the
same pile as one rank, its particles migrating across every face of the grid in both directions, the
periodic faces at x = 0 and y = 0 included, and a run restarted onto another grid goes on with the
same bits. The slabs alone (1 x 1 x K) are test_decomposition.py's.
"""
import os

import numpy as np
import pytest

import mpdem
from mpdem import config, domains
from mpdem.driver.simulation import Run

from mpi_helpers import PILE, run, serial_digest, shared_dir

# the grids of each rank count, frictional and frictionless in turn (the slabs, 1 x 1 x P: test_decomposition.py)
GRIDS = {2: [(2, 1, 1), (1, 2, 1)], 3: [(3, 1, 1), (1, 3, 1)], 4: [(2, 2, 1), (2, 1, 2)]}
STEPS = 3000


def _grids(comm):
    return GRIDS.get(comm.Get_size(), [])


def _sets(mu, steps=STEPS):
    """The pile's settings on any grid (the grid is set apart: one rank's reference has none)."""
    return PILE + [f"run.max_steps={steps}", "decomp.balance_by=count", f"contact.mu={mu}"]


def faces_crossed(dom):
    """Record, around ``dom._migrate``, every face a migrating row crosses: (axis, face, up) with face k
    the bound k of that axis (k = 0: the periodic face x = 0 or y = 0; in z the slab bound k) and up
    True when the row moves toward larger coordinates (across a periodic face: into column 0)."""
    seen, migrate = set(), dom._migrate
    grid = dom.grid

    def recording(state, keeper=None):
        x = state.x[:state.n_own]
        owner = dom.owner_of(x)
        mine = domains.coords(dom.rank, grid)
        for i in np.flatnonzero(owner != dom.rank):
            new = domains.coords(int(owner[i]), grid)
            for axis in range(3):
                a, b = int(mine[axis]), int(new[axis])
                if a == b:
                    continue
                if axis == 2:
                    seen.add((2, max(a, b), b > a))
                    continue
                # the face nearest the row among the column's two, 0 and P the same periodic face
                L, P = (dom.L_x, grid[0]) if axis == 0 else (dom.L_y, grid[1])
                k = int(round(x[i, axis] / (L / P))) % P
                seen.add((axis, k, b == k))
        migrate(state, keeper)
    dom._migrate = recording
    return seen


def every_face(grid):
    """All (axis, face, up) of ``grid``: both directions of each face between two domains."""
    want = set()
    for axis in (0, 1):
        if grid[axis] > 1:
            want |= {(axis, k, up) for k in range(grid[axis]) for up in (True, False)}
    want |= {(2, k, up) for k in range(1, grid[2]) for up in (True, False)}
    return want


@pytest.mark.parametrize("which", range(2))
def test_each_grid_pours_the_one_rank_pile_across_every_face(comm, which):
    grids = _grids(comm)
    if which >= len(grids):
        return          # no grid of this rank count here
    grid = grids[which]
    mu = 0.5 if which % 2 == 0 else 0.0
    cfg = config.load(None, _sets(mu) + [f"decomp.grid={list(grid)}"])
    base = shared_dir(comm)
    r = Run.new(cfg, os.path.join(base, "g"), comm, quiet=True)
    assert r.domain.grid == grid
    seen = faces_crossed(r.domain)
    r.run()
    s = r.finish()
    seen = set().union(*comm.allgather(seen))
    ref = serial_digest(config.load(None, _sets(mu)), os.path.join(base, "s"), comm)
    assert every_face(grid) <= seen, f"faces never crossed: {sorted(every_face(grid) - seen)}"
    if comm.Get_rank() == 0:
        assert s["digest"] == ref


def test_a_run_restarted_onto_another_grid_goes_on_with_the_same_bits(comm):
    """Half the steps on one grid, the state file read by the ranks of another grid (rows sent to their
    new columns first), the rest there: the one-rank digest of all the steps."""
    grids = _grids(comm)
    if len(grids) < 2:
        return
    base = shared_dir(comm)
    cfg = config.load(None, _sets(0.5, STEPS // 2) + [f"decomp.grid={list(grids[0])}"])
    run(cfg, os.path.join(base, "a"), comm)
    more = mpdem.restart(os.path.join(base, "a"), **{"run.max_steps": STEPS, "decomp.grid": list(grids[1])})
    ref = serial_digest(config.load(None, _sets(0.5)), os.path.join(base, "s"), comm)
    assert more.steps == STEPS
    assert comm.allgather(more.digest) == [ref] * comm.Get_size()


def test_a_grid_that_is_not_the_ranks_is_refused_on_every_rank(comm):
    P = comm.Get_size()
    cfg = config.load(None, PILE + ["run.max_steps=10", f"decomp.grid=[{P + 1}, 1, 1]"])
    with pytest.raises(mpdem.errors.ConfigError, match=rf"decomp.grid = \[{P + 1}, 1, 1\]: {P + 1} domains for {P} "):
        run(cfg, os.path.join(shared_dir(comm), "bad"), comm)


def write_tiles(path, tiles, L=6.0, n=5, layers=6, seed=3):
    """``tiles`` copies side by side in x of a loose stack of n x n layers on an n x n bed, each L x L:
    a sphere over each hollow of the layer below, 0.001 d above contact, jittered by 2e-4 d in x and y."""
    a = L / n
    grid = np.stack(np.meshgrid(np.arange(n), np.arange(n), indexing="ij"), -1).reshape(-1, 2) * a
    h = np.sqrt(1.0 - a * a / 2) + 0.001
    mob = np.concatenate([np.column_stack([(grid + a / 2 * (k % 2 == 0)) % L, np.full(n * n, 0.5 + (k + 1) * h)])
                          for k in range(layers)])
    mob[:, :2] = (mob[:, :2] + 2e-4 * np.random.default_rng(seed).uniform(-1, 1, (len(mob), 2))) % L
    one = np.concatenate([mob, np.column_stack([grid, np.full(n * n, 0.5)])])
    x = np.concatenate([one + [t * L, 0.0, 0.0] for t in range(tiles)])
    fixed = np.tile(np.r_[np.zeros(len(mob), np.uint8), np.ones(n * n, np.uint8)], tiles)
    from mpdem.io import tables
    tables.write_table(path, np.arange(len(x)), x, np.zeros_like(x), fixed)


def traffic(comm, tiles, grid, bulk_at_end):
    """A rank's bytes a step of the ghost refresh and of the reductions, bytes a rebuild of its exchanges and
    of its pickled calls, its rows (owned and ghost) and its engine's arrays, the largest over ``comm``'s
    ranks, in 600 steps of ``tiles`` stacks on ``grid``; then the end's bytes, with or without the bulk
    measurement (``output.bulk_at_end``)."""
    from mpi4py import MPI
    base = shared_dir(comm)
    path = os.path.join(base, "tiles.txt")
    if comm.Get_rank() == 0:
        write_tiles(path, tiles, layers=16)         # tall enough for a bulk slab between its margins
    comm.Barrier()
    cfg = config.load(None, ["run.max_steps=600", f"box.L_x={6.0 * tiles}", "box.L_y=6.0", f'run.initial_file="{path}"',
                             "output.progress_every=100000", "integration.skin=0.05", f"decomp.grid={list(grid)}",
                             f"output.bulk_at_end={str(bulk_at_end).lower()}"])
    r = Run.new(cfg, os.path.join(base, "run"), comm, quiet=True)
    before = r.domain.sent
    r.run()
    sent = {k: v - before[k] for k, v in r.domain.sent.items()}
    rebuilds = max(r.engine.n_rebuilds, 1)
    out = dict(refresh=sent["refresh"] / 600, reductions=sent["reductions"] / 600,
               exchanges=sent["exchanges"] / rebuilds, pickled=sent["pickled"] / rebuilds, rows=r.state.n_rows,
               memory=r.engine.memory_bytes())
    before = r.domain.sent
    s = r.finish()
    # the end: the digest by chunks of ids (each rank's rows once a field) and each rank's bulk measurement,
    # no gather of the pile
    out["end"] = sum(r.domain.sent.values()) - sum(before.values())
    if comm.Get_rank() == 0:
        assert ("bulk" in s) == bulk_at_end
    return {k: comm.allreduce(v, op=MPI.MAX) for k, v in out.items()}


@pytest.mark.parametrize("bulk_at_end", [True, False])
def test_a_rank_s_messages_and_memory_do_not_grow_with_the_pile(comm, bulk_at_end):
    """Weak scaling at 4 ranks: one stack on 2 ranks (2 x 1 x 1; each half of COMM_WORLD runs its own)
    against two stacks side by side on 4 (4 x 1 x 1): each rank holds the same box of the same stack, so
    its refresh, reductions, rebuild exchanges, rows and arrays stay put, within what the rank count itself
    adds (the all-to-all of counts and the balance's per-rank numbers); an all-to-all of the rows, a gather
    of every height or a halo of the whole bed would double them. So do the end's messages, with the bulk
    measurement (each rank's own, ``analysis.bulkpar``) and without (the digest by chunks of ids,
    ``checkpoint.digest_parts``)."""
    if comm.Get_size() != 4:
        return
    half = comm.Split(comm.Get_rank() // 2, comm.Get_rank())
    try:
        small = traffic(half, 1, (2, 1, 1), bulk_at_end)
    finally:
        half.Free()
    large = traffic(comm, 2, (4, 1, 1), bulk_at_end)
    assert small["refresh"] > 0 and small["exchanges"] > 0 and small["pickled"] > 0
    for k in ("refresh", "reductions", "rows", "memory"):
        assert 0.8 <= large[k] / small[k] <= 1.25, (k, small[k], large[k])
    # a rebuild's messages: what the stack's rows need, plus some numbers a rank (counts, seconds); the end's:
    # the rank's own rows and the ids' histogram, and the bulk's reductions and ghost flags
    for k in ("exchanges", "pickled", "end"):
        assert large[k] <= 1.25 * small[k] + 64 * comm.Get_size(), (k, small[k], large[k])


def test_the_bed_made_by_every_rank_together_is_the_one_rank_bed(comm, monkeypatch):
    """``bedcache.made_bed`` on every rank of the launch makes the bed together (``build.make_bed``: each
    rank settles the spheres of its domain, the grid chosen for the low layer), and gives every rank
    the bed one rank makes, bit for bit; made again, rank 0 reads it from the cache and every rank gets it."""
    from mpdem import bedcache, build
    from mpdem.parallel import Channel
    monkeypatch.setenv(bedcache.ENV, os.path.join(shared_dir(comm), "beds"))
    cfg = config.load(None, ["box.L_x=4", "box.L_y=4", "bed.settle_time=6", "run.max_steps=1"])
    made = bedcache.made_bed(cfg, net=Channel(comm))
    kept = bedcache.made_bed(cfg, net=Channel(comm))
    alone = build.make_bed(cfg)
    assert len(alone.x) > 10 and made.x.tobytes() == alone.x.tobytes() and made.note == alone.note
    assert kept.x.tobytes() == alone.x.tobytes() and "kept from its first making" in kept.note


TILED = ["box.L_x=10.0", "box.L_y=10.0", "pour.N=200", "pour.phi_i=0.1", "pour.K0=5.0", "pour.insertion=tiles",
         "pour.tile=4.0", "output.progress_every=100000", "stop.sample_interval=0.01", "run.max_steps=600",
         "contact.mu=0.5", "bed.settle_time=2"]


@pytest.mark.parametrize("grid", [None, "columns"])
def test_a_tiled_pour_filled_by_the_ranks_gives_the_one_rank_digest(comm, grid):
    """``pour.insertion = "tiles"``: each rank fills its share of the 8 tiles (2 x 2 x 2) and holds only
    its rows; the rows travel to their owners (on the grid chosen, and on columns): one rank's bits."""
    P = comm.Get_size()
    sets = TILED + ([f"decomp.grid=[{P}, 1, 1]"] if grid else [])
    base = shared_dir(comm)
    _, s = run(config.load(None, sets), os.path.join(base, "t"), comm)
    ref = serial_digest(config.load(None, TILED), os.path.join(base, "s"), comm)
    if comm.Get_rank() == 0:
        assert s["digest"] == ref
