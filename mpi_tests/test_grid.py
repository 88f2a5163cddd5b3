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

    def recording(state):
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
        migrate(state)
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
