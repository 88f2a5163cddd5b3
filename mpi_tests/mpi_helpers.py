"""Helpers shared by the MPI tests (imported as ``mpi_helpers``)."""
import os
import tempfile

from mpi4py import MPI

from mpdem.simulation import Run

PILE = ["box.L_x=5.0", "box.L_y=5.0", "pour.N=200", "pour.phi_i=0.3", "pour.K0=5.0",
        "output.progress_every=100000", "stop.sample_interval=0.01"]


def shared_dir(comm):
    return comm.bcast(tempfile.mkdtemp() if comm.Get_rank() == 0 else None)


def run(cfg, out, comm):
    r = Run(cfg, out, comm, quiet=True)
    r.prepare()
    r.run()
    return r, r.finish()


def serial_digest(cfg, out, comm):
    """The one-rank digest, computed on rank 0 and shared."""
    d = None
    if comm.Get_rank() == 0:
        _, s = run(cfg, out, MPI.COMM_SELF)
        d = s["digest"]
    return comm.bcast(d)
