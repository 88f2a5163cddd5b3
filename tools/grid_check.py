"""Grids of many domains against one rank, on a small pile: the check of decomp.grid past the 4 ranks of the tests.

    mpiexec -n 8 python tools/grid_check.py 2x2x2 4x2x1
    mpiexec -n 16 --oversubscribe python tools/grid_check.py 4x4x1 2x2x4 1x1x16

Each grid pours the pile of mpi_tests (200 spheres on a 5 d x 5 d bed, K0 = 5) for STEPS steps on every rank
of COMM_WORLD; rank 0 runs it alone once; each line says the grid, the migrations and whether the digest is
the one-rank digest. Exit status 1 if any differs.
"""
import os
import sys
import tempfile

import numpy as np
from mpi4py import MPI

from mpdem import config
from mpdem.driver.simulation import Run

PILE = ["box.L_x=5.0", "box.L_y=5.0", "pour.N=200", "pour.phi_i=0.3", "pour.K0=5.0", "output.progress_every=100000",
        "stop.sample_interval=0.01", "decomp.balance_by=count"]
STEPS = 3000


def digest(sets, out, comm):
    r = Run.new(config.load(None, sets), out, comm, quiet=True)
    r.run()
    return r, r.finish()


def main(grids):
    comm = MPI.COMM_WORLD
    base = comm.bcast(tempfile.mkdtemp() if comm.Get_rank() == 0 else None)
    sets = PILE + [f"run.max_steps={STEPS}"]
    ref = digest(sets, os.path.join(base, "one"), MPI.COMM_SELF)[1]["digest"] if comm.Get_rank() == 0 else None
    ref = comm.bcast(ref)
    bad = 0
    for g in grids:
        grid = [int(p) for p in g.split("x")]
        r, s = digest(sets + [f"decomp.grid={grid}"], os.path.join(base, g), comm)
        moved = int(r.domain.sum_int(np.array([r.domain.n_migrated]))[0])
        if comm.Get_rank() == 0:
            same = s["digest"] == ref
            bad += not same
            print(f"grid {g} on {comm.Get_size()} ranks: {moved} migrations, digest {s['digest'][:16]} "
                  f"{'=' if same else '!='} one rank's {ref[:16]}", flush=True)
    return comm.bcast(bad)


if __name__ == "__main__":
    sys.exit(1 if main(sys.argv[1:]) else 0)
