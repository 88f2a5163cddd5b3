"""Tests run under ``mpiexec -n K python -m pytest mpi_tests`` (K = 2, 3, 4).

Every rank runs every test; a failure on one rank fails the run. A failure on
any rank ends every rank at once, with the failure printed (the other ranks
may be waiting in a collective the failed rank will never reach: they would
hang until the Makefile's ``timeout``).
"""
import os
import sys

# numba sizes its thread pool at import to the cores a rank may use (one when
# mpiexec binds it); the ranks x threads test needs a pool of 2 on every rank
os.environ.setdefault("NUMBA_NUM_THREADS", "2")

import pytest  # noqa: E402
from mpi4py import MPI  # noqa: E402

from mpdem import memory, threads  # noqa: E402
from mpdem.kernels.calls import Bound  # noqa: E402

# every 16th kernel call through an overload numba chose compares its argument types with the chosen ones
Bound.check = 16

# the process's threads and allocator as a run sets them (``simulation``; the engines set neither): one
# thread, not numba's default of every core, whose idle threads would wait on a core the others use
threads.apply()
memory.return_freed_memory()


@pytest.fixture
def comm():
    return MPI.COMM_WORLD


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    rep = (yield).get_result()
    world = MPI.COMM_WORLD
    if rep.failed and world.Get_size() > 1:
        sys.stderr.write(f"\nmpi_tests: {item.nodeid} failed on rank {world.Get_rank()} of {world.Get_size()} "
                         f"({rep.when}); ending every rank\n{rep.longreprtext}\n")
        sys.stderr.flush()
        world.Abort(1)
