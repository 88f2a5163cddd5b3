"""Tests run under ``mpiexec -n K python -m pytest mpi_tests`` (K = 2, 3, 4).

Every rank runs every test; a failure on one rank fails the run. The
Makefile wraps the launch in ``timeout`` so a hang never blocks CI.
"""
import pytest
from mpi4py import MPI


@pytest.fixture
def comm():
    return MPI.COMM_WORLD
