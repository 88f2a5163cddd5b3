"""Domain decomposition: where particles live and how ranks agree.

This is the only module that moves particles between ranks (design.md,
invariant 3). The slab decomposition along z arrives with the MPI issue; this
version is the single-rank case, with the interface the engine uses:
``rebuild`` (migrate, rebalance, halo plan) at neighbour-list rebuilds,
``refresh`` (ghost x, v, omega) on other steps, and exact reductions.
"""
from __future__ import annotations

import numpy as np


class Domain:
    """Decomposition of the particles over the ranks of ``comm``.

    Parameters
    ----------
    comm : mpi4py communicator or None
        None (or a communicator of size 1) runs on one rank.
    """

    def __init__(self, comm=None):
        self.comm = comm
        self.size = 1 if comm is None else comm.Get_size()
        self.rank = 0 if comm is None else comm.Get_rank()
        if self.size > 1:
            raise NotImplementedError(
                f"mpdem runs on one rank only until the slab decomposition lands "
                f"(started with {self.size} ranks); use mpiexec -n 1")
        self.comm_seconds = 0.0

    # -- exact reductions (order independent, so rank-count independent) --
    def max(self, value):
        """Global maximum of a float (NaN wins, so a bad rank is seen by all)."""
        return value

    def min(self, value):
        return value

    def sum_int(self, arr):
        """Exact global sum of an int64 array (fixed-point accumulators, counts)."""
        return np.asarray(arr)

    def any(self, flag):
        return bool(flag)

    # -- particle movement --
    def rebuild(self, state):
        """Migrate, rebalance and rebuild the halo; on one rank: no ghosts."""
        state.n_rows = state.n_own

    def refresh(self, state):
        """Update ghost x, v, omega from their owners; on one rank: nothing."""

    def imbalance(self, state):
        """max / mean owned particles over ranks."""
        return 1.0
