"""Tests run under ``mpiexec -n K python -m pytest mpi_tests`` (K = 2, 3, 4).

Every rank runs every test; a failure on one rank fails the run. The
Makefile wraps the launch in ``timeout`` so a hang never blocks CI.
"""
import os

# numba sizes its thread pool at import to the cores a rank may use (one when
# mpiexec binds it); the ranks x threads test needs a pool of 2 on every rank
os.environ.setdefault("NUMBA_NUM_THREADS", "2")

import pytest  # noqa: E402
from mpi4py import MPI  # noqa: E402


@pytest.fixture
def comm():
    return MPI.COMM_WORLD
